// osd_loop — the peer: OpenSubdiv's uniform Loop refinement of a triangle mesh, in double
// precision, for tests and benchmarks of subdivd.
//
//   osd_loop [-l L] [--time N] [--origins] [--rules] [--chaikin] [--limit] INPUT
//
// INPUT is the text format of docs/TEXT_FORMAT.md, restricted to `v x y z` lines, 3-index
// `s i j k` lines (triangles) and `c` lines (`c i S`: vertex sharpness, a Far corner; `c i j S`:
// edge sharpness, a Far crease; given to Far as floats, 10 and more infinitely sharp); anything
// else is refused with exit status 2. --chaikin: Sdc::Options::CREASE_CHAIKIN.
// --limit: the `v` lines hold level L's points pushed to their limit positions by
// Far::PrimvarRefinerReal<double>::Limit (Sdc's Loop limit masks applied at level L), and a list
// `normals N` / `n x y z` (%.17g) follows the vertices: cross(tangent1, tangent2) of Limit's
// tangent masks, normalized (0 0 0 where that cross product vanishes).
//
// Default output: level L in the format of docs/TEXT_FORMAT.md (`level`, `vertices`, `v x y z`
// with %.17g, `triangles`, `t i j k`). --origins appends to each `v` line where the point comes
// from in level L-1, as sdlevel does: ` V i` (the child of vertex i) or ` E a b` (of edge a-b).
// --rules first prints how OpenSubdiv tagged the input (level 0): `vrule i RULE NM` per vertex
// (RULE smooth, dart, crease or corner; NM 1 if non-manifold) and `erule a b SHARP NM` per edge
// (SHARP 1 if infinitely sharp). With --time N: one line
//   osd_loop level=L faces_in=F faces_out=G seconds_best=S seconds_median=M
// with the best and median CLOCK_MONOTONIC wall time of N complete runs (topology construction
// and refinement plus position interpolation of every level; reading the file and freeing the
// result are not timed, as in bench/bench.c).
//
// OpenSubdiv's Loop scheme uses Loop's original vertex weights, beta(n) =
// (5/8 - (3/8 + cos(2 pi/n)/4)^2) / n; Warren's simplified weights are not available in it, so
// there is no --warren. Boundaries are VTX_BOUNDARY_EDGE_ONLY; all other Sdc options default.
//
// Notes on OpenSubdiv 3.5 (Debian libosd-dev):
// - Far::PrimvarRefinerReal<REAL> exists (far/primvarRefiner.h); Far::PrimvarRefiner is
//   PrimvarRefinerReal<float>, whose weights are floats and agree with exact Loop only to ~1e-7.
//   PrimvarRefinerReal<double> computes the weights in double as well.
// - With the default UniformOptions (orderVerticesFromFacesFirst = false) the vertices of level
//   l+1 are: the child of vertex i of level l at index i, then the children of the faces (none
//   for Loop), then the child of edge e at index N_l + e, in OpenSubdiv's own edge order.
// - The default error and warning callbacks print to stdout; they are sent to stderr here.
// - TopologyDescriptor does not check vertex indices: an index out of range corrupts memory,
//   so indices are checked while reading.
#include <opensubdiv/far/error.h>
#include <opensubdiv/far/primvarRefiner.h>
#include <opensubdiv/far/topologyDescriptor.h>

#include <time.h>

#include <algorithm>
#include <cmath>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

using namespace OpenSubdiv;

namespace {

const char *const kUsage =
    "usage: osd_loop [-l L] [--time N] [--origins] [--rules] [--chaikin] [--limit] INPUT";
const int kMaxLevel = 10;  // Far's limit for uniform refinement

// The primvar type Far::PrimvarRefinerReal<double> interpolates.
struct Vertex {
    double p[3];
    void Clear(void * = nullptr) { p[0] = p[1] = p[2] = 0.0; }
    void AddWithWeight(Vertex const &s, double w) {
        p[0] += w * s.p[0];
        p[1] += w * s.p[1];
        p[2] += w * s.p[2];
    }
};

[[noreturn]] void die(const std::string &msg) {
    std::fprintf(stderr, "osd_loop: %s\n", msg.c_str());
    std::exit(2);
}

bool g_far_error = false;

void on_far_error(Far::ErrorType, const char *message) {
    g_far_error = true;
    std::fprintf(stderr, "osd_loop: OpenSubdiv: %s\n", message);
}

void on_far_warning(const char *message) {
    std::fprintf(stderr, "osd_loop: OpenSubdiv warning: %s\n", message);
}

struct Mesh {
    std::vector<double> xyz;  // 3 per vertex
    std::vector<int> tris;    // 3 per triangle
    std::vector<int> crease_v, corner_v;  // 2 per crease, 1 per corner
    std::vector<float> crease_s, corner_s;
    bool chaikin = false;
};

// A whole-number command-line argument in [lo, hi].
int int_arg(const char *s, const char *what, int lo, int hi) {
    char *end = nullptr;
    errno = 0;
    long v = std::strtol(s, &end, 10);
    if (errno || end == s || *end || v < lo || v > hi)
        die(std::string("bad ") + what + " '" + s + "' (expected " + std::to_string(lo) + ".." +
            std::to_string(hi) + ")");
    return (int)v;
}

// True if nothing but whitespace or a comment is left in ss.
bool at_end(std::istringstream &ss) {
    std::string rest;
    return !(ss >> rest) || rest[0] == '#';
}

Mesh read_mesh(const char *path) {
    std::ifstream in(path);
    if (!in)
        die(std::string("cannot open ") + path);
    Mesh m;
    std::string line;
    int lineno = 0;
    while (std::getline(in, line)) {
        lineno++;
        std::string where = std::string(path) + ":" + std::to_string(lineno) + ": ";
        std::istringstream ss(line);
        std::string tag;
        if (!(ss >> tag) || tag[0] == '#')
            continue;
        if (tag == "v") {
            double x, y, z;
            if (!(ss >> x >> y >> z) || !at_end(ss))
                die(where + "bad vertex line: " + line);
            m.xyz.insert(m.xyz.end(), {x, y, z});
        } else if (tag == "s") {
            std::vector<long> ids;
            std::string tok;
            while (ss >> tok && tok[0] != '#') {
                char *end = nullptr;
                long v = std::strtol(tok.c_str(), &end, 10);
                if (end == tok.c_str() || *end)
                    die(where + "bad index '" + tok + "': " + line);
                ids.push_back(v);
            }
            if (ids.size() != 3)
                die(where + "only triangles (3-index s lines) are supported: " + line);
            for (long v : ids)
                if (v < 0 || v >= (long)(m.xyz.size() / 3))
                    die(where + "vertex index " + std::to_string(v) +
                        " is not a vertex defined above: " + line);
            if (ids[0] == ids[1] || ids[1] == ids[2] || ids[0] == ids[2])
                die(where + "degenerate triangle: " + line);
            m.tris.insert(m.tris.end(), ids.begin(), ids.end());
        } else if (tag == "c") {
            std::vector<double> x;
            double d;
            while (ss >> d)
                x.push_back(d);
            if ((x.size() != 2 && x.size() != 3) || !at_end(ss))
                die(where + "bad sharpness line: " + line);
            for (size_t k = 0; k + 1 < x.size(); k++)
                if (x[k] < 0 || x[k] >= (double)(m.xyz.size() / 3) || x[k] != (int)x[k])
                    die(where + "bad vertex index in: " + line);
            if (x.size() == 2) {
                m.corner_v.push_back((int)x[0]);
                m.corner_s.push_back((float)x[1]);
            } else {
                m.crease_v.insert(m.crease_v.end(), {(int)x[0], (int)x[1]});
                m.crease_s.push_back((float)x[2]);
            }
        } else {
            die(where + "unsupported line (only v, 3-index s and c): " + line);
        }
    }
    if (in.bad())
        die(std::string("error reading ") + path);
    if (m.tris.empty())
        die(std::string(path) + ": no triangles");
    return m;
}

struct Result {
    Far::TopologyRefiner *refiner = nullptr;
    std::vector<Vertex> verts;  // every level, one after the other, level 0 first
    size_t finest = 0;          // index of the first vertex of level L in verts
    Result() = default;
    Result(const Result &) = delete;
    Result &operator=(const Result &) = delete;
    ~Result() { delete refiner; }
};

// The timed job: build the topology, refine it uniformly to `level` and interpolate the
// positions of every level.
void run(const Mesh &m, int level, Result &r, bool full = false) {
    typedef Far::TopologyDescriptor Descriptor;
    int nv = (int)(m.xyz.size() / 3);
    int nf = (int)(m.tris.size() / 3);
    std::vector<int> per_face(nf, 3);
    Descriptor desc;
    desc.numVertices = nv;
    desc.numFaces = nf;
    desc.numVertsPerFace = per_face.data();
    desc.vertIndicesPerFace = m.tris.data();
    desc.numCreases = (int)m.crease_s.size();
    desc.creaseVertexIndexPairs = m.crease_v.data();
    desc.creaseWeights = m.crease_s.data();
    desc.numCorners = (int)m.corner_s.size();
    desc.cornerVertexIndices = m.corner_v.data();
    desc.cornerWeights = m.corner_s.data();

    Sdc::Options options;
    options.SetVtxBoundaryInterpolation(Sdc::Options::VTX_BOUNDARY_EDGE_ONLY);
    if (m.chaikin)
        options.SetCreasingMethod(Sdc::Options::CREASE_CHAIKIN);
    g_far_error = false;
    r.refiner = Far::TopologyRefinerFactory<Descriptor>::Create(
        desc, Far::TopologyRefinerFactory<Descriptor>::Options(Sdc::SCHEME_LOOP, options));
    if (!r.refiner || g_far_error)
        die("OpenSubdiv refused the mesh");
    Far::TopologyRefiner::UniformOptions uniform(level);
    uniform.fullTopologyInLastLevel = full;  // Limit() reads the last level's full topology
    r.refiner->RefineUniform(uniform);
    if (g_far_error)
        die("OpenSubdiv failed to refine the mesh");

    r.verts.resize(r.refiner->GetNumVerticesTotal());
    for (int i = 0; i < nv; i++)
        std::memcpy(r.verts[i].p, &m.xyz[3 * i], sizeof r.verts[i].p);
    Far::PrimvarRefinerReal<double> primvar(*r.refiner);
    Vertex *src = r.verts.data();
    for (int l = 1; l <= level; l++) {
        Vertex *dst = src + r.refiner->GetLevel(l - 1).GetNumVertices();
        primvar.Interpolate(l, src, dst);
        src = dst;
    }
    r.finest = (size_t)(src - r.verts.data());
}

double now() {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

}  // namespace

int main(int argc, char **argv) {
    int level = 2, reps = 0;
    bool origins = false, rules = false, chaikin = false, limit = false;
    const char *path = nullptr;
    for (int i = 1; i < argc; i++) {
        if (!std::strcmp(argv[i], "-l")) {
            if (i + 1 >= argc)
                die(kUsage);
            level = int_arg(argv[++i], "level", 0, kMaxLevel);
        } else if (!std::strcmp(argv[i], "--time")) {
            if (i + 1 >= argc)
                die(kUsage);
            reps = int_arg(argv[++i], "repetition count", 1, 1000000);
        } else if (!std::strcmp(argv[i], "--origins")) {
            origins = true;
        } else if (!std::strcmp(argv[i], "--rules")) {
            rules = true;
        } else if (!std::strcmp(argv[i], "--chaikin")) {
            chaikin = true;
        } else if (!std::strcmp(argv[i], "--limit")) {
            limit = true;
        } else if (argv[i][0] == '-' && argv[i][1]) {
            die(std::string("unknown option ") + argv[i] + "\n" + kUsage);
        } else if (path) {
            die(std::string("more than one input\n") + kUsage);
        } else {
            path = argv[i];
        }
    }
    if (!path)
        die(kUsage);
    Far::SetErrorCallback(on_far_error);
    Far::SetWarningCallback(on_far_warning);
    Mesh mesh = read_mesh(path);
    mesh.chaikin = chaikin;

    if (reps > 0) {
        std::vector<double> t(reps);
        int faces_out = 0;
        for (int k = 0; k < reps; k++) {
            Result r;
            double t0 = now();
            run(mesh, level, r);
            t[k] = now() - t0;  // freeing is not timed (as in bench/bench.c)
            faces_out = r.refiner->GetLevel(level).GetNumFaces();
        }
        std::sort(t.begin(), t.end());
        double median = t[reps / 2];  // the upper median for even N, as in bench/bench.c
        std::printf("osd_loop level=%d faces_in=%zu faces_out=%d seconds_best=%.6f "
                    "seconds_median=%.6f\n",
                    level, mesh.tris.size() / 3, faces_out, t[0], median);
        return 0;
    }

    Result r;
    run(mesh, level, r, limit);
    Far::TopologyLevel const &fin = r.refiner->GetLevel(level);
    if (rules) {
        Far::TopologyLevel const &l0 = r.refiner->GetLevel(0);
        for (int v = 0; v < l0.GetNumVertices(); v++) {
            Sdc::Crease::Rule k = l0.GetVertexRule(v);
            std::printf("vrule %d %s %d\n", v,
                        k == Sdc::Crease::RULE_SMOOTH ? "smooth" : k == Sdc::Crease::RULE_DART ? "dart"
                        : k == Sdc::Crease::RULE_CREASE ? "crease" : k == Sdc::Crease::RULE_CORNER ? "corner"
                        : "unknown", (int)l0.IsVertexNonManifold(v));
        }
        for (int e = 0; e < l0.GetNumEdges(); e++) {
            Far::ConstIndexArray ev = l0.GetEdgeVertices(e);
            std::printf("erule %d %d %d %d\n", ev[0], ev[1], (int)l0.IsEdgeInfSharp(e),
                        (int)l0.IsEdgeNonManifold(e));
        }
    }
    std::vector<Vertex> lim, tan1, tan2;
    if (limit) {
        lim.resize(fin.GetNumVertices());
        tan1.resize(lim.size());
        tan2.resize(lim.size());
        Far::PrimvarRefinerReal<double> primvar(*r.refiner);
        primvar.Limit(r.verts.data() + r.finest, lim, tan1, tan2);
        if (g_far_error)
            die("OpenSubdiv failed to evaluate the limit");
    }
    std::printf("level %d\nvertices %d\n", level, fin.GetNumVertices());
    // level L's vertices: the children of level L-1's vertices first, then of its edges (see the
    // notes above; Loop has no face children)
    int nvp = level > 0 ? r.refiner->GetLevel(level - 1).GetNumVertices() : fin.GetNumVertices();
    for (int i = 0; i < fin.GetNumVertices(); i++) {
        const double *p = limit ? lim[i].p : r.verts[r.finest + i].p;
        std::printf("v %.17g %.17g %.17g", p[0], p[1], p[2]);
        if (origins && level == 0) {
            std::printf(" I");
        } else if (origins && i < nvp) {
            std::printf(" V %d", i);
        } else if (origins) {
            Far::ConstIndexArray ev = r.refiner->GetLevel(level - 1).GetEdgeVertices(i - nvp);
            std::printf(" E %d %d", ev[0], ev[1]);
        }
        std::printf("\n");
    }
    if (limit) {
        std::printf("normals %d\n", fin.GetNumVertices());
        for (int i = 0; i < fin.GetNumVertices(); i++) {
            const double *a = tan1[i].p, *b = tan2[i].p;
            double n[3] = {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                           a[0] * b[1] - a[1] * b[0]};
            double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
            for (double &x : n)
                x = len > 0 ? x / len : 0.0;
            std::printf("n %.17g %.17g %.17g\n", n[0], n[1], n[2]);
        }
    }
    std::printf("triangles %d\n", fin.GetNumFaces());
    for (int f = 0; f < fin.GetNumFaces(); f++) {
        Far::ConstIndexArray fv = fin.GetFaceVertices(f);
        std::printf("t %d %d %d\n", fv[0], fv[1], fv[2]);
    }
    if (std::fflush(stdout) != 0 || std::ferror(stdout)) {
        std::fprintf(stderr, "osd_loop: error writing output\n");
        return 2;
    }
    return 0;
}
