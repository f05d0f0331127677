/* shim.cpp — extern "C" wrapper around TetGen 1.5 (see shim.h).
 *
 * TETLIBRARY must be defined before tetgen.h: without it the tetrahedralize(char *, ...) overload
 * is hidden and terminatetetgen() calls exit() instead of throwing. The tetgenio destructor frees
 * every list with delete[], so inputs are allocated with new[]. Switch strings are built with
 * fixed-point numbers because TetGen's own number parser does not read exponents reliably.
 */
#define TETLIBRARY
#include <tetgen.h>

#include "shim.h"
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <new>

/* The PLC: every point, every triangle a one-polygon facet. */
static void fill_plc(tetgenio &in, const double *xyz, uint32_t np, const uint32_t *tri, uint32_t nt)
{
    in.firstnumber = 0;
    in.numberofpoints = (int)np;
    in.pointlist = new REAL[3 * (size_t)np];
    std::memcpy(in.pointlist, xyz, 3 * (size_t)np * sizeof(double));
    in.numberoffacets = (int)nt;
    in.facetlist = new tetgenio::facet[nt];
    for (uint32_t i = 0; i < nt; i++) {
        tetgenio::facet *f = &in.facetlist[i];
        tetgenio::init(f);
        f->numberofpolygons = 1;
        f->polygonlist = new tetgenio::polygon[1];
        tetgenio::init(&f->polygonlist[0]);
        f->polygonlist[0].numberofvertices = 3;
        f->polygonlist[0].vertexlist = new int[3];
        for (int k = 0; k < 3; k++)
            f->polygonlist[0].vertexlist[k] = (int)tri[3 * (size_t)i + k];
    }
}

/* Append a switch letter with a positive number in fixed notation, 17 significant digits. */
static void add_number(char *sw, size_t cap, char letter, double v)
{
    int digits = 17 - (int)std::floor(std::log10(v)) - 1;
    if (digits < 1)
        digits = 1;
    if (digits > 80)
        digits = 80;
    size_t n = std::strlen(sw);
    std::snprintf(sw + n, cap - n, "%c%.*f", letter, digits, v);
}

extern "C" int sdtg_detect(const double *xyz, uint32_t np, const uint32_t *tri, uint32_t nt,
                           uint32_t **faces, uint32_t *nfaces)
{
    *faces = NULL;
    *nfaces = 0;
    try {
        tetgenio in, out;
        fill_plc(in, xyz, np, tri, nt);
        char sw[] = "pdzQ";
        tetrahedralize(sw, &in, &out);
        if (out.numberoftrifaces > 0) {
            size_t n = (size_t)out.numberoftrifaces;
            *faces = (uint32_t *)std::malloc(3 * n * sizeof(uint32_t));
            if (!*faces)
                return SDTG_SHIM_NOMEM;
            for (size_t i = 0; i < 3 * n; i++)
                (*faces)[i] = (uint32_t)out.trifacelist[i];
            *nfaces = (uint32_t)n;
        }
        return 0;
    } catch (int code) {
        return code > 0 ? code : 2;
    } catch (std::bad_alloc &) {
        return SDTG_SHIM_NOMEM;
    }
}

extern "C" int sdtg_tetrahedralize(const double *xyz, uint32_t np, const uint32_t *tri, uint32_t nt,
                                   double max_volume, double min_ratio, int verbose,
                                   double **points, uint32_t *npoints, uint32_t **tets,
                                   uint32_t *ntets)
{
    *points = NULL;
    *tets = NULL;
    *npoints = *ntets = 0;
    try {
        tetgenio in, out;
        fill_plc(in, xyz, np, tri, nt);
        char sw[256] = "pYz";
        if (min_ratio > 0)
            add_number(sw, sizeof sw, 'q', min_ratio);
        if (max_volume > 0)
            add_number(sw, sizeof sw, 'a', max_volume);
        if (!verbose)
            std::strcat(sw, "Q");
        tetrahedralize(sw, &in, &out);
        if (out.numberofcorners != 4 && out.numberoftetrahedra > 0)
            return 2;
        size_t n = (size_t)out.numberofpoints, t = (size_t)out.numberoftetrahedra;
        *points = (double *)std::malloc((3 * n + 1) * sizeof(double));
        *tets = (uint32_t *)std::malloc((4 * t + 1) * sizeof(uint32_t));
        if (!*points || !*tets) {
            std::free(*points);
            std::free(*tets);
            *points = NULL;
            *tets = NULL;
            return SDTG_SHIM_NOMEM;
        }
        std::memcpy(*points, out.pointlist, 3 * n * sizeof(double));
        for (size_t i = 0; i < 4 * t; i++)
            (*tets)[i] = (uint32_t)out.tetrahedronlist[i];
        *npoints = (uint32_t)n;
        *ntets = (uint32_t)t;
        return 0;
    } catch (int code) {
        return code > 0 ? code : 2;
    } catch (std::bad_alloc &) {
        return SDTG_SHIM_NOMEM;
    }
}
