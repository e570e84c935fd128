// Surface voxelization with OpenVDB's mesh-to-volume (Debian package libopenvdb-dev 10.0.1), a
// peer in docs/BENCHMARKS.md. Our own harness code: it only calls the library.
//
// Build: scripts/peers/build.sh DEST (or by hand, with libopenvdb-dev libtbb-dev libboost-dev:
//   g++ -O2 -std=c++17 openvdb_surface.cpp -o openvdb_surface -lopenvdb -ltbb -lImath-3_1)
// Run:
//   openvdb_surface MESH.ply GRID OUT.vdb
// MESH.ply is the binary PLY that scripts/bench_peers.sh converts each input to (float x y z,
// uchar r g b per vertex; `list uchar int` faces, triangles only). The cube grid spans the
// mesh bbox's longest side with GRID voxels. It builds an UNSIGNED distance narrow band of
// half-width 1 voxel (tools::meshToUnsignedDistanceField), then counts
//   - "surface" voxels: centre within sqrt(3)/2 voxel of the surface (the circumscribed-sphere
//     test: a superset of the voxels a triangle touches, i.e. close to a 26-separating shell),
//   - "thin" voxels: centre within 1/2 voxel (about a 6-separating shell),
// prunes everything else to inactive background, and writes that grid (OUT.vdb, blosc/zip as the
// library defaults) so the output size is that of a surface-only grid. The last line of its
// output, `VOXELS N`, is the surface count.
#include <openvdb/openvdb.h>
#include <openvdb/tools/MeshToVolume.h>
#include <openvdb/tools/Prune.h>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

using namespace openvdb;

static double now() {
    return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

int main(int argc, char** argv) {
    if (argc < 4) { std::fprintf(stderr, "usage: %s mesh.ply grid out.vdb\n", argv[0]); return 2; }
    const int N = std::atoi(argv[2]);
    double t0 = now();
    std::ifstream in(argv[1], std::ios::binary);
    std::string line; size_t nv = 0, nf = 0;
    while (std::getline(in, line)) {
        std::istringstream ss(line); std::string a, b; ss >> a >> b;
        if (a == "element" && b == "vertex") ss >> nv;
        if (a == "element" && b == "face") ss >> nf;
        if (a == "end_header") break;
    }
    std::vector<Vec3s> pts(nv);
    std::vector<Vec3I> tris(nf);
    std::vector<Vec4I> quads;
    for (size_t i = 0; i < nv; i++) {
        char buf[15]; in.read(buf, 15); float p[3]; std::memcpy(p, buf, 12);
        pts[i] = Vec3s(p[0], p[1], p[2]);
    }
    for (size_t i = 0; i < nf; i++) {
        char buf[13]; in.read(buf, 13); int f[3]; std::memcpy(f, buf + 1, 12);
        tris[i] = Vec3I(f[0], f[1], f[2]);
    }
    Vec3s lo(1e30f), hi(-1e30f);
    for (auto& p : pts) for (int k = 0; k < 3; k++) { lo[k] = std::min(lo[k], p[k]); hi[k] = std::max(hi[k], p[k]); }
    float ext = std::max(hi[0] - lo[0], std::max(hi[1] - lo[1], hi[2] - lo[2]));
    double vs = ext / N;
    double t1 = now();

    initialize();
    math::Transform::Ptr xf = math::Transform::createLinearTransform(vs);
    xf->postTranslate(Vec3d(lo[0] + 0.5 * vs, lo[1] + 0.5 * vs, lo[2] + 0.5 * vs)); // cell centres
    FloatGrid::Ptr g = tools::meshToUnsignedDistanceField<FloatGrid>(*xf, pts, tris, quads, 1.0f);
    double t2 = now();

    const float rs = float(vs * std::sqrt(3.0) / 2.0), rt = float(vs * 0.5);
    size_t band = 0, surf = 0, thin = 0;
    for (auto it = g->tree().beginLeaf(); it; ++it) {
        for (auto v = it->beginValueOn(); v; ++v) {
            band++;
            float d = *v;
            if (d <= rs) surf++;
            if (d <= rt) thin++;
            if (d > rs) v.setValueOff();
        }
    }
    tools::pruneInactive(g->tree());
    double t3 = now();
    g->setName("surface");
    io::File f(argv[3]);
    GridPtrVec grids; grids.push_back(g);
    f.write(grids); f.close();
    double t4 = now();
    std::printf("triangles %zu grid %d voxel_size %.9g\n", nf, N, vs);
    std::printf("band_active %zu surface_voxels %zu thin_voxels %zu\n", band, surf, thin);
    std::printf("time_read %.3f time_mesh2vol %.3f time_count %.3f time_write %.3f\n",
                t1 - t0, t2 - t1, t3 - t2, t4 - t3);
    std::printf("VOXELS %zu\n", surf);
    return 0;
}
