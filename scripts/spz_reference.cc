// Loads and writes SPZ with Niantic's reference library (github.com/nianticlabs/spz, src/cc),
// for scripts/make_writer_fixtures.py. Built by that script against a checkout of the library:
//
//   g++ -O2 -std=c++17 -I SPZ/src scripts/spz_reference.cc SPZ/src/cc/load-spz.cc \
//       SPZ/src/cc/splat-types.cc -lz -lzstd -o spz_reference
//
//   spz_reference dump IN.spz          one line per Gaussian, in PLY (RDF) axes:
//                                      x y z  log-scales(3)  quaternion x y z w  opacity logit
//                                      f_dc(3)  SH rest (coefficient-major, channel fastest)
//   spz_reference write IN.ply OUT.spz VERSION
//                                      the library's own writer (PLY axes in, its defaults)
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "cc/load-spz.h"

int main(int argc, char **argv) {
  if (argc >= 3 && std::strcmp(argv[1], "dump") == 0) {
    spz::UnpackOptions options;
    options.to = spz::CoordinateSystem::RDF;  // the PLY convention, splatraj's
    spz::GaussianCloud g = spz::loadSpz(std::string(argv[2]), options);
    if (g.numPoints == 0) {
      std::fprintf(stderr, "spz_reference: could not load %s\n", argv[2]);
      return 1;
    }
    const int shPerPoint = static_cast<int>(g.sh.size()) / g.numPoints;
    std::printf("%d %d %d\n", g.numPoints, g.shDegree, g.antialiased ? 1 : 0);
    for (int i = 0; i < g.numPoints; ++i) {
      for (int k = 0; k < 3; ++k) std::printf("%.9g ", g.positions[3 * i + k]);
      for (int k = 0; k < 3; ++k) std::printf("%.9g ", g.scales[3 * i + k]);
      for (int k = 0; k < 4; ++k) std::printf("%.9g ", g.rotations[4 * i + k]);
      std::printf("%.9g ", g.alphas[i]);
      for (int k = 0; k < 3; ++k) std::printf("%.9g ", g.colors[3 * i + k]);
      for (int k = 0; k < shPerPoint; ++k) std::printf("%.9g ", g.sh[shPerPoint * i + k]);
      std::printf("\n");
    }
    return 0;
  }
  if (argc >= 5 && std::strcmp(argv[1], "write") == 0) {
    spz::UnpackOptions unpack;  // keeps the PLY's own (RDF) axes
    spz::GaussianCloud g = spz::loadSplatFromPly(std::string(argv[2]), unpack);
    spz::PackOptions pack;
    pack.from = spz::CoordinateSystem::RDF;
    pack.version = static_cast<uint32_t>(std::atoi(argv[4]));
    return spz::saveSpz(g, pack, std::string(argv[3])) ? 0 : 1;
  }
  std::fprintf(stderr, "usage: spz_reference dump IN.spz | write IN.ply OUT.spz VERSION\n");
  return 2;
}
