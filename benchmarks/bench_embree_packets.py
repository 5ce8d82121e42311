"""Benchmark: would Embree's ray packets trace the renderer's rays faster, and with the same answers?

The renderer traces one ray at a time (embreex's ``run`` loops over
``rtcIntersect1`` without the GIL).  Embree 4, the version embreex ships,
has no stream interface (``rtcIntersect1M`` and the like are gone); it
exports packets of 4, 8 and 16 rays, ``rtcIntersect4/8/16``.  One ctypes
call per packet costs more than the packet saves, so this benchmark
measures the packets where they would run: a C loop over the renderer's own
rays (nefertiti, 72 views at 256 x 256, in Z-order; ``cc`` compiles it
against the Embree library embreex ships), in turns with the same loop
over ``rtcIntersect1``, on one thread, in the pinned device
(``isa=sse2``) and in Embree's own choice for this CPU.  Packets are traced
with Embree's default (incoherent) query flag and with
``RTC_RAY_QUERY_FLAG_COHERENT``.  It counts the rays whose face, distance
or barycentrics differ from the single rays'.

    python benchmarks/bench_embree_packets.py [--meshes-dir ../shared/meshes] [--repeats 5]
"""

from __future__ import annotations

import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from bench_render import candidate_rays
from benchlib import arguments, run

from meshsal import load_mesh
from meshsal.views.cameras import view_rig

# Single rays, then packets of WIDTH, over the same rays, ROUNDS times; prints seconds and differences.
_SOURCE = r"""
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
typedef void *H;
H rtcNewDevice(const char *); H rtcNewScene(H); void rtcSetSceneFlags(H, int); H rtcNewGeometry(H, int);
void *rtcSetNewGeometryBuffer(H, int, unsigned, int, size_t, size_t); void rtcCommitGeometry(H);
unsigned rtcAttachGeometry(H, H); void rtcCommitScene(H); int rtcGetDeviceError(H);
void rtcIntersect1(H, void *, void *); void rtcIntersect4(const int *, H, void *, void *);
void rtcIntersect8(const int *, H, void *, void *); void rtcIntersect16(const int *, H, void *, void *);
/* RTCRayHit: ray (12 words), hit Ng, u, v, primID, geomID, instID, instPrimID; padded. */
typedef struct { float w[32]; } __attribute__((aligned(16))) Ray1;
static void *slurp(const char *dir, const char *name, size_t *n) {
  char path[4096]; snprintf(path, sizeof path, "%s/%s", dir, name);
  FILE *f = fopen(path, "rb"); if (!f) { perror(path); exit(2); }
  fseek(f, 0, SEEK_END); *n = ftell(f); fseek(f, 0, SEEK_SET);
  void *b = malloc(*n); if (fread(b, 1, *n, f) != *n) exit(2); fclose(f); return b;
}
static double now(void) { struct timespec t; clock_gettime(CLOCK_MONOTONIC, &t); return t.tv_sec + 1e-9 * t.tv_nsec; }
int main(int argc, char **argv) {
  const char *dir = argv[1]; int W = atoi(argv[3]), rounds = atoi(argv[4]);
  /* RTCIntersectArguments: flags (RTC_RAY_QUERY_FLAG_COHERENT = 1 << 16), all features, no context or callbacks. */
  struct { int flags; unsigned features; void *context, *filter, *intersect; float min_width; } arguments = {
      atoi(argv[5]) ? 1 << 16 : 0, ~0u, 0, 0, 0, 0};
  size_t nv, nf, no, nd;
  float *V = slurp(dir, "V", &nv), *O = slurp(dir, "O", &no), *D = slurp(dir, "D", &nd);
  unsigned *F = slurp(dir, "F", &nf);
  nv /= 12; nf /= 12; size_t k = no / 12;
  H dev = rtcNewDevice(argv[2]), scene = rtcNewScene(dev), g = rtcNewGeometry(dev, 0);
  float *vb = rtcSetNewGeometryBuffer(g, 1, 0, 0x9003, 16, nv);
  unsigned *ib = rtcSetNewGeometryBuffer(g, 0, 0, 0x5003, 12, nf);
  for (size_t i = 0; i < nv; i++) { memcpy(vb + 4 * i, V + 3 * i, 12); vb[4 * i + 3] = 0; }
  memcpy(ib, F, nf * 12);
  rtcCommitGeometry(g); rtcAttachGeometry(scene, g); rtcCommitScene(scene);
  float *one = malloc(16 * k), *many = malloc(16 * k); /* t, u, v, primID per ray */
  static float b[32 * 16] __attribute__((aligned(64)));
  int valid[16] __attribute__((aligned(64)));
  for (int r = 0; r < rounds; r++) {
    double t0 = now();
    for (size_t i = 0; i < k; i++) {
      Ray1 x; float *w = x.w; unsigned *u = (unsigned *)w;
      memcpy(w, O + 3 * i, 12); w[3] = 0; memcpy(w + 4, D + 3 * i, 12); w[7] = 0; w[8] = INFINITY;
      u[9] = ~0u; u[10] = 0; u[11] = 0; u[17] = u[18] = u[19] = ~0u;
      rtcIntersect1(scene, &x, NULL);
      one[4 * i] = w[8]; one[4 * i + 1] = w[15]; one[4 * i + 2] = w[16]; memcpy(one + 4 * i + 3, u + 17, 4);
    }
    double t1 = now();
    for (size_t i = 0; i < k; i += W) {
      unsigned *u = (unsigned *)b;
      for (int j = 0; j < W; j++) {
        size_t q = i + j < k ? i + j : i; valid[j] = i + j < k ? -1 : 0;
        for (int c = 0; c < 3; c++) { b[c * W + j] = O[3 * q + c]; b[(4 + c) * W + j] = D[3 * q + c]; }
        b[3 * W + j] = 0; b[7 * W + j] = 0; b[8 * W + j] = INFINITY;
        u[9 * W + j] = ~0u; u[10 * W + j] = 0; u[11 * W + j] = 0; u[17 * W + j] = u[18 * W + j] = u[19 * W + j] = ~0u;
      }
      if (W == 4) rtcIntersect4(valid, scene, b, &arguments);
      else if (W == 8) rtcIntersect8(valid, scene, b, &arguments);
      else rtcIntersect16(valid, scene, b, &arguments);
      for (int j = 0; j < W && i + j < k; j++) {
        float *m = many + 4 * (i + j);
        m[0] = b[8 * W + j]; m[1] = b[15 * W + j]; m[2] = b[16 * W + j]; memcpy(m + 3, u + 17 * W + j, 4);
      }
    }
    double t2 = now();
    size_t face = 0, dist = 0, bary = 0;
    for (size_t i = 0; i < k; i++) {
      float *a = one + 4 * i, *c = many + 4 * i;
      if (memcmp(a + 3, c + 3, 4)) face++;
      else if (memcmp(a, c, 4)) dist++;
      else if (memcmp(a + 1, c + 1, 8)) bary++;
    }
    printf("%.6f %.6f %zu %zu %zu %zu %d\n", t1 - t0, t2 - t1, k, face, dist, bary, rtcGetDeviceError(dev));
  }
  return 0;
}
"""


def embree_library() -> Path:
    """The Embree library file embreex ships (the one ``meshsal.mesh.embree`` calls through ctypes)."""
    import embreex

    shipped = sorted((Path(embreex.__file__).parent.parent / "embreex.libs").glob("libembree4*.so*"))
    if not shipped:
        raise SystemExit("bench_embree_packets: embreex ships no libembree4 here")
    return shipped[0]


def main(argv=None) -> int:
    parser = arguments(__doc__, repeats=5, repeats_help="rounds of single rays then packets (median)")
    parser.add_argument("--size", type=int, default=256)
    args = parser.parse_args(argv)
    compiler = shutil.which("cc") or shutil.which("gcc")
    if compiler is None:
        print("bench_embree_packets: no C compiler (cc): nothing measured", file=sys.stderr)
        return 1
    mesh = load_mesh(args.meshes_dir / "nefertiti.obj")
    cameras = [c for s in view_rig() for c in s]
    rays = candidate_rays(mesh, cameras, args.size)
    library = embree_library()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        np.ascontiguousarray(mesh.vertices, np.float32).tofile(work / "V")
        np.ascontiguousarray(mesh.faces, np.uint32).tofile(work / "F")
        np.vstack([o for o, _ in rays]).astype(np.float32).tofile(work / "O")
        np.vstack([np.broadcast_to(d, o.shape) for o, d in rays]).astype(np.float32).tofile(work / "D")
        (work / "packets.c").write_text(_SOURCE)
        binary = work / "packets"
        subprocess.run(
            [compiler, "-O2", "-o", str(binary), str(work / "packets.c"), str(library), f"-Wl,-rpath,{library.parent}"],
            check=True,
        )
        for config, label in (("isa=sse2", "pinned (isa=sse2)"), ("", "Embree's choice for this CPU")):
            for width, coherent in ((w, c) for c in (0, 1) for w in (4, 8, 16)):
                out = subprocess.run(
                    [str(binary), str(work), config, str(width), str(args.repeats), str(coherent)],
                    check=True,
                    capture_output=True,
                    text=True,
                ).stdout.split("\n")
                runs = np.array([[float(x) for x in line.split()] for line in out if line.strip()])
                packet = f"{width}{', coherent' if coherent else ''}"
                if runs[:, 6].any():
                    rows.append(f"| {label} | {packet} | Embree error {int(runs[-1, 6])} | | | | |")
                    continue
                single, packets = statistics.median(runs[:, 0]), statistics.median(runs[:, 1])
                ratio = runs[:, 0] / runs[:, 1]
                k, face, dist, bary = (int(v) for v in runs[-1, 2:6])
                rows.append(
                    f"| {label} | {packet} | {k / single / 1e6:.2f} | {k / packets / 1e6:.2f} | "
                    f"{np.median(ratio):.2f}x ({ratio.min():.2f}-{ratio.max():.2f}) | {face} / {dist} | "
                    f"{bary} ({bary / k:.1%}) |"
                )
    body = (
        f"nefertiti: {mesh.n_faces} faces; the renderer's {sum(len(o) for o, _ in rays)} rays of "
        f"{len(cameras)} views at {args.size}^2, one thread, a fast (non-robust) scene; {args.repeats} rounds, "
        f"each single rays then packets; medians, and the range of the rounds' ratios.\n\n"
        "| device | packet | Mrays/s, single | Mrays/s, packets | packets against single | rays whose face / "
        "distance differ | rays whose barycentrics differ |\n|---|---:|---:|---:|---:|---:|---:|\n" + "\n".join(rows)
    )
    print(body)
    return 0


if __name__ == "__main__":
    run("bench_embree_packets", "Embree's ray packets against single rays on the renderer's rays", main)
