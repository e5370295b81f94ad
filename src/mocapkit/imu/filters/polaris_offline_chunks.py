"""``polaris`` offline, piece by piece: the smoother's steps (O2-O5 of
:mod:`mocapkit.imu.filters.polaris_offline`) over a recording held in a :class:`Store`,
``chunk`` samples at a time, each sequential step carrying its state from piece to piece.

Every step is sequential in one direction: the forward pass, strapdown and forward
low-pass and heading filter in time order, the backward pass, backward low-pass and
backward heading filter in reverse order, and the fusions sample by sample. Run piece by
piece with the state carried, each gives the same numbers, to the bit, as over the whole
arrays at once (tested). With a :class:`RamStore` and one piece this *is* the in-memory
smoother (:func:`mocapkit.imu.filters.polaris_offline.smooth`); with a :class:`DiskStore`
the recording and the intermediate arrays (51 columns: ~400 bytes a sample) live in
files in a temporary directory, read and written a piece at a time, so memory is bounded
by the piece whatever the recording's length (issue 16: an hour at 1 kHz is 3.6 M
samples, ~1.5 GB on disk while it runs).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from mocapkit._spill import RowFile
from mocapkit._validate import FloatArray
from mocapkit.errors import DataError
from mocapkit.geometry import quat_from_two_vectors, quat_mul
from mocapkit.imu.filters import polaris_params as pp
from mocapkit.imu.filters.polaris_engine import initial_linear_acc, run_pass, start
from mocapkit.imu.filters.polaris_offline_kernels import (
    heading_fusion_kernel,
    heading_kernel,
    iir_kernel,
    inclination_kernel,
    smoothed_strapdown_kernel,
)
from mocapkit.imu.filters.polaris_params import (
    PolarisCore,
    PolarisParams,
    butterworth2,
    pack_state,
)

_UP = np.array([0.0, 0.0, 1.0])

# columns of each array the steps keep (float64)
COLUMNS = {
    "gyr": 3, "acc": 3, "mag": 3, "dt": 1, "time": 1,  # the validated inputs, time [s]
    "aux_f": 8, "aux_b": 8,  # the two passes' aux (O2); aux_b in reverse time order
    "bias": 3, "q_IS": 4, "acc_I": 3,  # (O3), (O4)
    "acc_fw": 3, "acc_lp": 3, "q6": 4,  # (O4): forward low-pass, zero-phase, 6D result
    "head_f": 2, "head_b": 2,  # (O5); head_b in reverse time order
}  # fmt: skip


class Store:
    """Named (N, columns) float64 arrays, read and written by row range."""

    def read(self, name: str, a: int, b: int) -> FloatArray:
        raise NotImplementedError

    def write(self, name: str, a: int, rows: FloatArray) -> None:
        raise NotImplementedError


class RamStore(Store):
    """The arrays in memory (the in-memory smoother); inputs are used without a copy."""

    def __init__(self, n: int, **inputs: FloatArray) -> None:
        self.n = n
        self.arrays: dict[str, FloatArray] = {
            k: np.asarray(v, dtype=float).reshape(n, COLUMNS[k]) for k, v in inputs.items()
        }

    def read(self, name: str, a: int, b: int) -> FloatArray:
        return self.arrays[name][a:b]

    def write(self, name: str, a: int, rows: FloatArray) -> None:
        if name not in self.arrays:
            self.arrays[name] = np.empty((self.n, COLUMNS[name]))
        self.arrays[name][a : a + len(rows)] = rows.reshape(len(rows), COLUMNS[name])


class DiskStore(Store):
    """The arrays in raw files (row-major float64) in ``directory``, read with plain file
    reads (not memory maps, whose pages would count as the process's memory)."""

    def __init__(self, directory: str | Path) -> None:
        self.directory = Path(directory)
        self.files: dict[str, RowFile] = {}

    def _file(self, name: str) -> RowFile:
        if name not in self.files:
            self.files[name] = RowFile(self.directory / f"{name}.f64", (COLUMNS[name],))
        return self.files[name]

    def read(self, name: str, a: int, b: int) -> FloatArray:
        return self._file(name).read(a, b)

    def write(self, name: str, a: int, rows: FloatArray) -> None:
        self._file(name).write(a, np.asarray(rows).reshape(len(rows), COLUMNS[name]))

    def close(self) -> None:
        for f in self.files.values():
            f.close()
        self.files.clear()


class Piece(NamedTuple):
    """Samples ``start .. stop`` of the smoothed result."""

    start: int
    stop: int
    q6: FloatArray
    q9: FloatArray | None
    bias: FloatArray


def smooth_pieces(
    params: PolarisParams,
    store: Store,
    n: int,
    use_acc: np.ndarray,
    use_mag: np.ndarray,
    has_mag: bool,
    chunk: int,
) -> Iterator[Piece]:
    """The offline estimate of the validated inputs ``gyr``, ``acc``, ``mag``, ``dt`` in
    ``store`` (``use_acc``, ``use_mag``: (N,) flags in memory), piece by piece in time
    order (module docstring)."""
    c = pp.coefficients(params)
    c[pp.C_MAG_DELAY] = 0.0
    chunk = max(int(chunk), 1)
    s = _Steps(params, c, store, n, use_acc, use_mag, has_mag, chunk)
    s.passes()
    s.strapdown()
    s.lowpass()
    if not has_mag:
        for a, b in s.ranges():
            yield Piece(a, b, store.read("q6", a, b), None, store.read("bias", a, b))
        return
    s.headings()
    for a, b in s.ranges():
        q6 = store.read("q6", a, b)
        fwd = store.read("head_f", a, b)
        bwd = s.reversed_rows("head_b", a, b)
        gap = bwd[:, 0] - fwd[:, 0]
        diff = np.arctan2(np.sin(gap), np.cos(gap))
        q9 = np.empty((b - a, 4))
        heading_fusion_kernel(np.ascontiguousarray(q6), np.ascontiguousarray(fwd), bwd, diff, q9)
        yield Piece(a, b, q6, q9, store.read("bias", a, b))


class _Steps:
    def __init__(
        self, params: PolarisParams, c: FloatArray, store: Store, n: int, use_acc: np.ndarray,
        use_mag: np.ndarray, has_mag: bool, chunk: int,
    ) -> None:  # fmt: skip
        self.params, self.c, self.store, self.n, self.chunk = params, c, store, n, chunk
        self.use_acc = np.asarray(use_acc, dtype=bool)
        # (O1) the magnetometer moved earlier by its delay (the last reading held at the end)
        self.delay = params.mag_delay_samples if has_mag and n > params.mag_delay_samples else 0
        um = np.asarray(use_mag, dtype=bool)
        if self.delay > 0:
            um = np.concatenate([um[self.delay :], np.repeat(um[-1:], self.delay)])
        self.use_mag = um

    def ranges(self) -> Iterator[tuple[int, int]]:
        for a in range(0, self.n, self.chunk):
            yield a, min(a + self.chunk, self.n)

    def reversed_ranges(self) -> Iterator[tuple[int, int]]:
        """Reverse-time index ranges [r0, r1) in order (r = n - 1 - k)."""
        yield from self.ranges()

    def reversed_rows(self, name: str, a: int, b: int) -> FloatArray:
        """Samples a..b (time order) of an array kept in reverse time order."""
        return np.ascontiguousarray(self.store.read(name, self.n - b, self.n - a)[::-1])

    def mag(self, a: int, b: int) -> FloatArray:
        """The delay-aligned magnetometer, samples a..b."""
        n, d = self.n, self.delay
        lo, hi = min(a + d, n), min(b + d, n)
        rows = self.store.read("mag", lo, hi)
        if hi - lo < b - a:  # past the end: the last reading held
            last = self.store.read("mag", n - 1, n)
            rows = np.concatenate([rows, np.repeat(last, b - a - (hi - lo), axis=0)])
        return np.ascontiguousarray(rows)

    def backward_inputs(self, r0: int, r1: int) -> tuple[FloatArray, ...]:
        """The reversed recording's rows r0..r1: the gyroscope negated and shifted by one
        sample (reading k turns from k - 1 to k), time steps shifted alike."""
        n = self.n
        a, b = n - r1, n - r0  # the samples they come from, in time order
        hi = min(b + 1, n)
        g = self.store.read("gyr", a, hi)[::-1]
        d = self.store.read("dt", a, hi)[::-1, 0]
        gyr_b = np.zeros((r1 - r0, 3))
        dt_b = np.empty(r1 - r0)
        if r0 == 0:  # the reversed recording's first sample: no turn, the last step
            gyr_b[1:] = -g[: r1 - r0 - 1]
            dt_b[0] = d[0]
            dt_b[1:] = d[: r1 - r0 - 1]
        else:
            gyr_b[:] = -g[: r1 - r0]
            dt_b[:] = d[: r1 - r0]
        acc_b = np.ascontiguousarray(self.store.read("acc", a, b)[::-1])
        mag_b = np.ascontiguousarray(self.mag(a, b)[::-1])
        return gyr_b, acc_b, mag_b, dt_b

    # (O2) forward and backward passes of the online filter (6D: only the bias is used)
    def passes(self) -> None:
        usable = np.flatnonzero(self.use_acc)
        if usable.size == 0:
            raise DataError(
                "acc: no usable sample (all zero-norm or saturated) to initialise the "
                "inclination; start the run where the accelerometer works"
            )
        st, n = self.store, self.n
        first, last = int(usable[0]), int(usable[-1])
        core = PolarisCore()
        acc_first = st.read("acc", first, first + 1)
        gyr0 = st.read("gyr", 0, 1)[0]
        lin2 = initial_linear_acc(acc_first, st.read("gyr", first, first + 1),
                                  float(st.read("dt", 0, 1)[0, 0]))  # fmt: skip
        start(self.c, core, quat_from_two_vectors(acc_first[0], _UP), gyr0, acc_first[0], lin2)
        for a, b in self.ranges():
            aux = self._pass(core, st.read("gyr", a, b), st.read("acc", a, b),
                             self.mag(a, b), st.read("dt", a, b)[:, 0], self.use_acc[a:b],
                             self.use_mag[a:b])  # fmt: skip
            st.write("aux_f", a, aux)
        # backward: the reversed recording's first usable sample is the last one
        core = PolarisCore()
        rf = n - 1 - last
        g_rf = self.backward_inputs(rf, rf + 1)[0]
        acc_last = st.read("acc", last, last + 1)
        first_b = self.backward_inputs(0, 1)
        lin2 = initial_linear_acc(acc_last, g_rf, float(first_b[3][0]))
        start(self.c, core, quat_from_two_vectors(acc_last[0], _UP), first_b[0][0], acc_last[0],
              lin2)  # fmt: skip
        ua, um = self.use_acc[::-1], self.use_mag[::-1]
        for r0, r1 in self.reversed_ranges():
            gyr_b, acc_b, mag_b, dt_b = self.backward_inputs(r0, r1)
            aux = self._pass(core, gyr_b, acc_b, mag_b, dt_b, np.ascontiguousarray(ua[r0:r1]),
                             np.ascontiguousarray(um[r0:r1]))  # fmt: skip
            st.write("aux_b", r0, aux)

    def _pass(self, core: PolarisCore, *arrays: Any) -> FloatArray:
        gyr, acc, mag, dt, ua, um = (np.ascontiguousarray(x) for x in arrays)
        return run_pass(self.c, core, "fast", gyr, acc, mag, dt, ua, um, False, True).aux

    # (O3) smoothed bias, (O4) strapdown with it and the accelerometer in I
    def strapdown(self) -> None:
        st = self.store
        q = np.array([1.0, 0.0, 0.0, 0.0])
        for a, b in self.ranges():
            m = b - a
            bias, q_IS, acc_I = np.empty((m, 3)), np.empty((m, 4)), np.empty((m, 3))
            smoothed_strapdown_kernel(
                np.ascontiguousarray(st.read("gyr", a, b)),
                np.ascontiguousarray(st.read("acc", a, b)),
                np.ascontiguousarray(st.read("dt", a, b)[:, 0]),
                np.ascontiguousarray(st.read("aux_f", a, b)),
                self.reversed_rows("aux_b", a, b),
                q, bias, q_IS, acc_I,
            )  # fmt: skip
            st.write("bias", a, bias)
            st.write("q_IS", a, q_IS)
            st.write("acc_I", a, acc_I)

    # (O4) the zero-phase low-pass of the accelerometer in I, its inclination -> q6
    def lowpass(self) -> None:
        st, n = self.store, self.n
        b0, b1, b2, a1, a2 = butterworth2(self.params.offline_tau_acc, self.params.dt)
        unit = np.array([b1 - a1 + b2 - a2, b2 - a2])
        zi = np.empty((3, 2))
        for a, b in self.ranges():
            x = self._filled(a, b)
            if a == 0:
                zi[:] = x[0][:, None] * unit[None, :]
            out = np.empty_like(x)
            iir_kernel(x, b0, b1, b2, a1, a2, zi, False, out)
            st.write("acc_fw", a, out)
        last = st.read("acc_fw", n - 1, n)[0]
        zi[:] = last[:, None] * unit[None, :]
        for a, b in reversed(list(self.ranges())):
            x = np.ascontiguousarray(st.read("acc_fw", a, b))
            out = np.empty_like(x)
            iir_kernel(x, b0, b1, b2, a1, a2, zi, True, out)
            q_IS = np.ascontiguousarray(st.read("q_IS", a, b))
            q6 = np.empty((b - a, 4))
            if not inclination_kernel(out, q_IS, q6):  # antiparallel or broken: numpy
                q6 = quat_mul(quat_from_two_vectors(out, np.broadcast_to(_UP, out.shape)), q_IS)
            st.write("acc_lp", a, out)
            st.write("q6", a, q6)

    def _filled(self, a: int, b: int) -> FloatArray:
        """``acc_I`` a..b with unusable rows linearly interpolated between the usable
        neighbours (held at the ends): ``np.interp`` over those neighbours alone gives
        what it gives over the whole recording."""
        x = np.ascontiguousarray(self.store.read("acc_I", a, b))
        ok = self.use_acc[a:b]
        if ok.all():
            return x
        idx = [int(i) for i in np.flatnonzero(ok) + a]
        before = np.flatnonzero(self.use_acc[:a])
        after = np.flatnonzero(self.use_acc[b:])
        rows = [x[i - a] for i in idx]
        if before.size:
            idx.insert(0, int(before[-1]))
            rows.insert(0, self.store.read("acc_I", idx[0], idx[0] + 1)[0])
        if after.size:
            j = int(after[0]) + b
            idx.append(j)
            rows.append(self.store.read("acc_I", j, j + 1)[0])
        xp = np.asarray(idx, dtype=float)
        fp = np.asarray(rows)
        t = np.arange(a, b, dtype=float)
        return np.ascontiguousarray(np.stack([np.interp(t, xp, fp[:, j]) for j in range(3)], 1))

    # (O5) the heading filter forward and backward over q6
    def headings(self) -> None:
        st, n = self.store, self.n
        state = pack_state(PolarisCore())
        for a, b in self.ranges():
            q6 = np.ascontiguousarray(st.read("q6", a, b))
            out = np.empty((b - a, 2))
            heading_kernel(self.c, state, q6, self.mag(a, b), self._rate2(a, b),
                           np.ascontiguousarray(st.read("dt", a, b)[:, 0]),
                           np.ascontiguousarray(self.use_mag[a:b]), out)  # fmt: skip
            st.write("head_f", a, out)
        state = pack_state(PolarisCore())
        um = self.use_mag[::-1]
        for r0, r1 in self.reversed_ranges():
            a, b = n - r1, n - r0
            _, _, mag_b, dt_b = self.backward_inputs(r0, r1)
            out = np.empty((r1 - r0, 2))
            heading_kernel(self.c, state, np.ascontiguousarray(st.read("q6", a, b)[::-1]),
                           mag_b, np.ascontiguousarray(self._rate2(a, b)[::-1]), dt_b,
                           np.ascontiguousarray(um[r0:r1]), out)  # fmt: skip
            st.write("head_b", r0, out)

    def _rate2(self, a: int, b: int) -> FloatArray:
        rate = self.store.read("gyr", a, b) - self.store.read("bias", a, b)
        return np.ascontiguousarray(np.einsum("ij,ij->i", rate, rate))


def default_workdir() -> str:
    """Where the disk store's files go: ``MOCAPKIT_TMPDIR``, else the system's temporary
    directory (``TMPDIR``)."""
    import tempfile

    return os.environ.get("MOCAPKIT_TMPDIR") or tempfile.gettempdir()


__all__ = ["COLUMNS", "DiskStore", "Piece", "RamStore", "Store", "default_workdir", "smooth_pieces"]
