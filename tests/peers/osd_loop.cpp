// osd_loop — the peer: OpenSubdiv's uniform Loop refinement of a triangle mesh, in double
// precision (Far::PrimvarRefinerReal<double>), for tests and benchmarks of subdivd.
//
//   osd_loop [-l L] [--time N] INPUT
//
// INPUT is the text format of docs/TEXT_FORMAT.md (v lines and 3-index s lines only). Prints the
// level-L vertices and triangles in the same format, or with --time N the best and median wall
// time of N complete runs (topology refinement + interpolation of every level; no file I/O).
// OpenSubdiv uses Loop's original weights; boundaries are VTX_BOUNDARY_EDGE_ONLY.
#include <opensubdiv/far/primvarRefiner.h>
#include <opensubdiv/far/topologyDescriptor.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

using namespace OpenSubdiv;

struct Vertex {
    double p[3];
    void Clear(void * = nullptr) { p[0] = p[1] = p[2] = 0; }
    void AddWithWeight(Vertex const &s, double w) {
        p[0] += w * s.p[0];
        p[1] += w * s.p[1];
        p[2] += w * s.p[2];
    }
};

static void die(const char *msg, const std::string &what = "") {
    std::fprintf(stderr, "osd_loop: %s%s\n", msg, what.c_str());
    std::exit(2);
}

struct Result {
    Far::TopologyRefiner *refiner;
    std::vector<Vertex> verts;   // all levels, level after level
    size_t finest;               // offset of the finest level
};

static Result run(const std::vector<double> &xyz, const std::vector<int> &tris, int level) {
    typedef Far::TopologyDescriptor Descriptor;
    Sdc::Options options;
    options.SetVtxBoundaryInterpolation(Sdc::Options::VTX_BOUNDARY_EDGE_ONLY);
    int nf = (int)tris.size() / 3;
    std::vector<int> per(nf, 3);
    Descriptor desc;
    desc.numVertices = (int)xyz.size() / 3;
    desc.numFaces = nf;
    desc.numVertsPerFace = per.data();
    desc.vertIndicesPerFace = tris.data();
    Far::TopologyRefiner *refiner = Far::TopologyRefinerFactory<Descriptor>::Create(
        desc, Far::TopologyRefinerFactory<Descriptor>::Options(Sdc::SCHEME_LOOP, options));
    if (!refiner)
        die("OpenSubdiv refused the mesh");
    refiner->RefineUniform(Far::TopologyRefiner::UniformOptions(level));
    Result r{refiner, std::vector<Vertex>(refiner->GetNumVerticesTotal()), 0};
    for (int i = 0; i < desc.numVertices; i++)
        std::memcpy(r.verts[i].p, &xyz[3 * i], 3 * sizeof(double));
    Far::PrimvarRefinerReal<double> primvar(*refiner);
    Vertex *src = r.verts.data();
    for (int l = 1; l <= level; l++) {
        Vertex *dst = src + refiner->GetLevel(l - 1).GetNumVertices();
        primvar.Interpolate(l, src, dst);
        src = dst;
    }
    r.finest = (size_t)(src - r.verts.data());
    return r;
}

int main(int argc, char **argv) {
    int level = 2, reps = 0;
    const char *path = nullptr;
    for (int i = 1; i < argc; i++) {
        if (!std::strcmp(argv[i], "-l") && i + 1 < argc)
            level = std::atoi(argv[++i]);
        else if (!std::strcmp(argv[i], "--time") && i + 1 < argc)
            reps = std::atoi(argv[++i]);
        else if (argv[i][0] == '-')
            die("usage: osd_loop [-l L] [--time N] INPUT");
        else
            path = argv[i];
    }
    if (!path || level < 0 || level > 10)
        die("usage: osd_loop [-l L] [--time N] INPUT");
    std::ifstream in(path);
    if (!in)
        die("cannot open ", path);
    std::vector<double> xyz;
    std::vector<int> tris;
    std::string line;
    while (std::getline(in, line)) {
        std::istringstream ss(line);
        std::string tag;
        if (!(ss >> tag) || tag[0] == '#')
            continue;
        if (tag == "v") {
            double x, y, z;
            if (!(ss >> x >> y >> z))
                die("bad vertex line: ", line);
            xyz.insert(xyz.end(), {x, y, z});
        } else if (tag == "s") {
            std::vector<int> ids;
            int v;
            while (ss >> v)
                ids.push_back(v);
            if (ids.size() != 3)
                die("only triangles are supported: ", line);
            tris.insert(tris.end(), ids.begin(), ids.end());
        } else {
            die("unsupported line: ", line);
        }
    }
    if (reps > 0) {
        std::vector<double> t;
        int nout = 0;
        for (int r = 0; r < reps; r++) {
            auto t0 = std::chrono::steady_clock::now();
            Result res = run(xyz, tris, level);
            auto t1 = std::chrono::steady_clock::now();
            t.push_back(std::chrono::duration<double>(t1 - t0).count());
            nout = res.refiner->GetLevel(level).GetNumFaces();
            delete res.refiner;
        }
        std::sort(t.begin(), t.end());
        std::printf("osd_loop level=%d faces_in=%zu faces_out=%d seconds_best=%.6f seconds_median=%.6f\n",
                    level, tris.size() / 3, nout, t[0], t[t.size() / 2]);
        return 0;
    }
    Result res = run(xyz, tris, level);
    Far::TopologyLevel const &fin = res.refiner->GetLevel(level);
    std::printf("level %d\nvertices %d\n", level, fin.GetNumVertices());
    for (int i = 0; i < fin.GetNumVertices(); i++) {
        const double *p = res.verts[res.finest + i].p;
        std::printf("v %.17g %.17g %.17g\n", p[0], p[1], p[2]);
    }
    std::printf("triangles %d\n", fin.GetNumFaces());
    for (int f = 0; f < fin.GetNumFaces(); f++) {
        Far::ConstIndexArray fv = fin.GetFaceVertices(f);
        std::printf("t %d %d %d\n", fv[0], fv[1], fv[2]);
    }
    delete res.refiner;
    return 0;
}
