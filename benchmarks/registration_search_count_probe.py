"""A probe that chose nothing (2026-12-05): how much would a compiled count save the coarse search (``search.py``)?

The search's joint histograms are one gather and one ``np.bincount`` per rotation over every (translation step, fixed
sample) pair. This probe compiles the same count as 8 lines of C (``h[s][min(fbk[i] + canvas[base[i] + offset[s]],
K)]++``, the per-step cells never materialised) with the system's C compiler, calls it through ctypes in place of the
numpy lines, and times the whole search (``_Run.grid``, median of 11) both ways on the first case of each dimension of
the ``report`` split (the speed benchmark's first pairs), checking that the grids are identical.
docs/registration_history.md ("Speed, every run") says why it was not built in.

    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/registration_search_count_probe.py
"""

from __future__ import annotations

import ctypes
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import registration_corpus as corpus  # noqa: E402

import topomatch.stages.registration.register as R  # noqa: E402
from topomatch.stages.registration import search  # noqa: E402
from topomatch.stages.registration.params import RegisterParams  # noqa: E402

C_COUNT = """
#include <stdint.h>
void grid_counts(const int64_t *base, const int64_t *off, const int32_t *fbk, const int32_t *canvas, int64_t K,
                 int64_t n, int64_t b, int64_t *out) {
    for (int64_t s = 0; s < b; s++) {
        int64_t *row = out + s * (K + 1);
        const int32_t *c = canvas + off[s];
        for (int64_t i = 0; i < n; i++) { int64_t v = (int64_t)fbk[i] + c[base[i]]; row[v < K ? v : K]++; }
    }
}
"""


def compiled_count(folder: Path):
    """The C count built into ``folder`` and loaded (ctypes)."""
    (folder / "count.c").write_text(C_COUNT)
    subprocess.run(["cc", "-O3", "-shared", "-fPIC", "-o", str(folder / "count.so"), str(folder / "count.c")],
                   check=True)
    lib = ctypes.CDLL(str(folder / "count.so"))
    pointer = ctypes.c_void_p
    lib.grid_counts.argtypes = [pointer] * 4 + [ctypes.c_int64] * 3 + [pointer]
    return lib.grid_counts


def scores_with(count):
    """``SearchImages.scores_and_overlaps`` with the count done by ``count`` (same inputs, same outputs)."""
    def scores_and_overlaps(self, theta, steps):
        K, b, steps = self.K, len(steps), np.asarray(steps, dtype=np.intp)
        ends = self._cells(np.asarray(theta, dtype=np.float64), steps[[0, -1]])  # pads the canvas for the cube
        base = np.ascontiguousarray(ends[0], dtype=np.int64)
        offsets = np.ascontiguousarray((steps - steps[0]) @ self._strides, dtype=np.int64)
        h = np.zeros((b, K + 1), dtype=np.int64)
        count(base.ctypes.data, offsets.ctypes.data, self._fbk.ctypes.data, self._bins_canvas.ctypes.data, K,
              len(base), b, h.ctypes.data)
        h = h[:, :K].reshape(b, -1, self._moving_bins).astype(np.float64)
        return search.batch_jensen_tsallis2(h), h.sum(axis=(1, 2)) / self.n_samples
    return scores_and_overlaps


def median_grid_ms(run) -> tuple[float, object]:
    seconds = []
    for _ in range(11):
        run._grids.clear()
        t = time.perf_counter()
        grid = run.grid()
        seconds.append(time.perf_counter() - t)
    return 1e3 * sorted(seconds)[5], grid


def main() -> None:
    numpy_scores = search.SearchImages.scores_and_overlaps
    count = compiled_count(Path(tempfile.mkdtemp(prefix="topomatch-count-")))
    for dim in (2, 3):
        spec = next(s for s in corpus.plan_split("report", dim) if corpus.source_available(s.source))
        case = corpus.build_case(spec)
        params = R.for_dimension(RegisterParams(), dim)
        run = R._Run(case.fixed, case.moving, params, R.sample_mask(case.fixed, params), None)
        search.SearchImages.scores_and_overlaps = numpy_scores
        numpy_ms, numpy_grid = median_grid_ms(run)
        search.SearchImages.scores_and_overlaps = scores_with(count)
        c_ms, c_grid = median_grid_ms(run)
        same = (np.array_equal(numpy_grid.raw, c_grid.raw, equal_nan=True)
                and np.array_equal(numpy_grid.overlaps, c_grid.overlaps))
        print(f"{dim}D {spec.id}: search numpy {numpy_ms:.1f} ms, compiled count {c_ms:.1f} ms, identical grids {same}")
    search.SearchImages.scores_and_overlaps = numpy_scores


if __name__ == "__main__":
    main()
