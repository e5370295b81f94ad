"""Which coordinates the visible markers determine, frame by frame.

Structural rule: a revolute DOF is determined in a frame when a visible tracked marker sits
on the segment it moves or on any segment below it (or a coordinate task holds it); the
root needs three visible tracked markers. A coordinate reported from several DOFs
(:mod:`mocapkit.markers.coordinates`) is determined when all of them are. Direct marker
control holds undetermined DOFs at their angle; outputs show them as NaN.
"""

from __future__ import annotations

from collections.abc import Collection, Sequence

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.human_model import HumanModel
from mocapkit.markers.coordinates import CoordinateMap


def dof_marker_table(
    human: HumanModel, names: Sequence[str], tracked: Collection[str]
) -> tuple[np.ndarray, np.ndarray]:
    """CSR table over the revolute DOFs (``q[7:]`` order): ``idx[ptr[k]:ptr[k + 1]]`` are the
    columns (into ``names``) of the ``tracked`` markers at or below the segment DOF k moves."""
    seg_of = human.dof_segment()
    below = {seg: human.descendants(seg) for seg in set(seg_of.values())}
    ptr = [0]
    idx: list[int] = []
    for dof in human.dof_names:
        segs = below[seg_of[dof]]
        idx += [i for i, n in enumerate(names) if n in tracked and human.markers[n][0] in segs]
        ptr.append(len(idx))
    return np.array(ptr, dtype=np.int64), np.array(idx, dtype=np.int64)


def dof_determined(
    human: HumanModel,
    names: Sequence[str],
    tracked: Collection[str],
    X: FloatArray,
    held: Collection[str] = (),
) -> tuple[np.ndarray, np.ndarray]:
    """Per frame: root determined (N,) and revolute DOFs determined (N, n_dof) by the visible
    tracked markers of X (N, M, 3); DOFs in ``held`` (coordinate tasks) always are."""
    vis = np.isfinite(X[..., 0])
    cols = [i for i, n in enumerate(names) if n in tracked]
    root = vis[:, cols].sum(axis=1) >= 3
    ptr, idx = dof_marker_table(human, names, tracked)
    out = np.zeros((X.shape[0], len(human.dof_names)), dtype=bool)
    for k, dof in enumerate(human.dof_names):
        if dof in held:
            out[:, k] = True
        elif ptr[k + 1] > ptr[k]:
            out[:, k] = vis[:, idx[ptr[k] : ptr[k + 1]]].any(axis=1)
    return root, out


def column_determined(cmap: CoordinateMap, root: np.ndarray, dofs: np.ndarray) -> np.ndarray:
    """(N, K) bool over the reported coordinates from :func:`dof_determined`'s masks."""
    out = np.zeros((root.shape[0], len(cmap.names)), dtype=bool)
    for col, dep in enumerate(cmap.depends):
        out[:, col] = root if not dep else dofs[:, list(dep)].all(axis=1)
    return out
