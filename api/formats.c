/* formats.c — the table of level output formats: one row per format, read by everything that
 * names one (out.h): the `format=` query and its error message, the Content-Type and
 * Content-Disposition of a level response, the offline mode's choice by output extension, the
 * sizes in GET /levels/{L}/stats and `subdivd --list-formats` (which the tests compare with the
 * OpenAPI document and the Python client).
 *
 * To add a format: write its writer in its own file (an init function filling out_stream, see
 * out_internal.h), declare the init in out_internal.h and add its row here. The first row is the
 * default format. A format's name is its extension without the dot, so `-o level.NAME` picks it.
 */
#include "out_internal.h"
#include <stdio.h>
#include <string.h>

const out_format out_formats[] = {
    {"glb", "model/gltf-binary", ".glb", "inline", true, out_glb_init},
    {"gltf", "model/gltf+json", ".gltf", "inline", true, out_gltf_init},
    {"vtu", "application/vnd.unstructured-grid+xml", ".vtu", "attachment", false, out_vtu_init},
    {"vtk", "application/octet-stream", ".vtk", "attachment", false, out_vtk_init},
    {"json", "application/json", ".json", "inline", false, out_json_init},
    {NULL, NULL, NULL, NULL, false, NULL},
};

const out_format *out_format_find(const char *name)
{
    for (const out_format *f = out_formats; f->name; f++)
        if (!strcmp(name, f->name))
            return f;
    return NULL;
}

const out_format *out_format_for_path(const char *path)
{
    const char *dot = strrchr(path, '.');
    for (const out_format *f = out_formats; dot && f->name; f++)
        if (!strcmp(dot, f->extension))
            return f;
    return NULL;
}

char *out_format_list(char *buf, size_t cap, bool extensions, const char *sep, const char *last)
{
    size_t n = 0;
    buf[0] = 0;
    for (const out_format *f = out_formats; f->name && n < cap; f++) {
        const char *between = f == out_formats ? "" : f[1].name ? sep : last;
        n += (size_t)snprintf(buf + n, cap - n, "%s%s", between, extensions ? f->extension : f->name);
    }
    return buf;
}
