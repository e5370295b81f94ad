"""A marker set for labels no preset knows: segments from the labels, checked and completed
by the motion (rigid clusters), or a clear refusal with the YAML to write.

1. **Labels.** Most labelling conventions name the side (``L``/``R`` or ``Left``/``Right``
   as a prefix, ``_L``/``.L`` as a suffix) and the landmark (``ASI``, ``Knee``, ``TH1``,
   ``Heel``...). :func:`classify_label` maps the landmark to a segment with a table of
   the keywords of Plug-in Gait, CGM2, the CMU/Vicon set, OpenSim's gait2392 and
   Rajagopal sets and the Qualisys/Visual3D names (:data:`KEYWORDS`).
2. **Rigid clusters.** Markers on one segment keep their distances; over the motion the
   spread (standard deviation) of each pair's distance separates segment mates (a few
   millimetres of skin motion) from markers across a joint (centimetres). A marker whose
   label names no landmark joins the segment it moves rigidly with; one whose label was
   read wrong (it does not move with its segment's other markers, but with another
   segment's) moves there. Both are reported.
3. **Offsets** start from the segment's typical marker position (registration on the
   static trial, or the estimation from the motion, replaces them).

Never silent: :func:`auto_markerset` returns what it chose (the report lists every marker
and how it was placed), and :func:`require_lower_limbs` refuses a set that leaves the
pelvis, a thigh, a shank or a foot without markers, with the markers and a YAML template
in the message.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import yaml

from mocapkit._validate import FloatArray
from mocapkit.body.markersets import MarkerSet, MarkerSpec
from mocapkit.errors import DataError

# landmark keyword (regex on the label without its side) -> segment (s: the side)
KEYWORDS: tuple[tuple[str, str], ...] = (
    (
        r"(ASI|ASIS|PSI|PSIS|SACR|SACRUM|SACRAL|S2|PELV.*|ILIAC|ICT|GTR|TROCH.*|HJC|WT|FWT|BWT)",
        "pelvis",
    ),
    (r"(FHD|BHD|HEAD|TEMPLE|VERTEX|FOREHEAD|EAR|GLABELLA)", "head"),
    (
        r"(C7|T10|T8|T12|CLAV|STRN|STERN.*|XIPH.*|BAK|BACK|SJN|SXS|JUG.*|LUMB.*|L5|L1)",
        "thorax",
    ),
    (r"(SHO|SHOULDER|ACR|ACROM.*|ACROMION|CLAVICLE)", "clavicle_s"),
    (
        r"(UPA|UA\d*|HUM.*|ARM|UPPERARM|BICEPS?|[LM]?ELB|[LM]?ELBOW|LEL|MEL|EPI|LHE|MHE)",
        "upper_arm_s",
    ),
    (r"(FRM|FA\d*|FOREARM|WRA|WRB|WRIST.*|WR|RAD.*|ULN.*|STY.*|USP|RSP)", "forearm_s"),
    (r"(FIN|HAND|MCP\d*|MH\d*|MC\d*|FING.*|THUMB)", "hand_s"),
    (
        r"(THI|THIGH.*|TH\d+|THAP|THAD|FEM.*|KNE|[LM]?KNEE.*|KNM|LFC|MFC|FLE|FME|LEPI|MEPI)",
        "thigh_s",
    ),
    (
        r"(TIB|TB\d+|TIAP|TIAD|SHN|SHANK.*|SH\d+|ANK|[LM]?ANKLE.*|MAL|LMAL|MMAL|MED|FIB.*|FAL|TAM|"
        r"LM|MM|KJC)",
        "shank_s",
    ),
    (r"(HEE|HEEL|CAL|CALC.*|TOE|TOE.*|MT\d*|MET.*|MIDFOOT.*|FOOT.*|FM\d|VMH|AJC)", "foot_s"),
)
_COMPILED = tuple((re.compile(rf"^{pat}$", re.IGNORECASE), seg) for pat, seg in KEYWORDS)
_SIDE_PREFIX = re.compile(r"^(L|R|Left|Right|LEFT|RIGHT|left|right|l|r)(?=[A-Z0-9_.\- ]|$)")
_SIDE_SUFFIX = re.compile(r"[_.\- ](L|R|Left|Right|left|right|l|r)$")
LOWER_LIMB = ("pelvis", "thigh_r", "shank_r", "foot_r", "thigh_l", "shank_l", "foot_l")
# typical marker position per segment (metres, segment frame, 1.75 m subject; y: left)
_TYPICAL: dict[str, tuple[float, float, float]] = {
    "pelvis": (0.0, 0.0, 0.09),
    "head": (0.0, 0.0, 0.08),
    "thorax": (0.0, 0.0, 0.15),
    "clavicle_s": (-0.07, 0.15, 0.02),
    "upper_arm_s": (0.0, 0.05, -0.15),
    "forearm_s": (0.0, 0.04, -0.15),
    "hand_s": (0.0, 0.0, -0.07),
    "thigh_s": (0.0, 0.07, -0.25),
    "shank_s": (0.0, 0.05, -0.25),
    "foot_s": (0.08, 0.0, 0.02),
}
# landmarks whose place on the segment is known (y: the marker's side, +left), as in the
# presets; other markers start at the segment's typical place
_LANDMARKS: tuple[tuple[str, tuple[float, float, float]], ...] = (
    (r"ASI|ASIS", (0.088, 0.124, 0.093)),
    (r"PSI|PSIS", (-0.09, 0.045, 0.10)),
    (r"S2|SACR|SACRUM|SACRAL", (-0.10, 0.0, 0.10)),
    (r"KNE|KNEE|LKNEE|LFC|LEPI|FLE", (0.0, 0.05, -0.424)),
    (r"KNM|MKNEE|MFC|MEPI|FME", (0.0, -0.05, -0.424)),
    (r"ANK|ANKLE|LANKLE|LMAL|LM|FAL", (-0.005, 0.04, -0.43)),
    (r"MED|MANKLE|MMAL|MM|TAM", (0.005, -0.035, -0.42)),
    (r"HEE|HEEL|CAL|CALC.*", (-0.019, 0.0, 0.019)),
    (r"TOE|MT2|FM2", (0.165, 0.0, 0.01)),
    (r"MT5|FM5|VMH", (0.13, 0.045, 0.005)),
    (r"MT1|FM1", (0.16, -0.03, 0.005)),
    (r"SHO|SHOULDER|ACR|ACROM.*", (-0.07, 0.15, 0.02)),
    (r"ELB|ELBOW|LEL|LHE", (0.0, 0.04, -0.283)),
    (r"MELB|MELBOW|MEL|MHE", (0.0, -0.04, -0.283)),
    (r"WRA|WRIST|RSP", (0.0, 0.035, -0.27)),
    (r"WRB|USP", (0.0, -0.025, -0.27)),
    (r"C7", (-0.03, 0.0, 0.245)),
    (r"T10", (-0.07, 0.0, 0.06)),
    (r"CLAV|SJN", (0.10, 0.0, 0.19)),
    (r"STRN|STERN.*|SXS", (0.12, 0.0, 0.0)),
)
_LANDMARK_RE = tuple((re.compile(rf"^({pat})$", re.IGNORECASE), off) for pat, off in _LANDMARKS)
RIGID_SPREAD_M = 0.012  # distance spread of two markers on one segment (skin motion)


@dataclass(frozen=True)
class LabelGuess:
    label: str
    side: str | None  # "r", "l" or None (midline)
    core: str  # the label without its side
    segment: str | None  # None: no landmark keyword recognised


def _split_side(label: str) -> tuple[str | None, str]:
    text = label.strip()
    m = _SIDE_SUFFIX.search(text)
    if m:
        return m.group(1)[0].lower(), text[: m.start()]
    m = _SIDE_PREFIX.match(text)
    if m and len(text) > len(m.group(1)):
        core = text[len(m.group(1)) :].lstrip("_.- ")
        return m.group(1)[0].lower(), core
    return None, text


def classify_label(label: str) -> LabelGuess:
    """The segment a label names (side taken from ``L``/``R`` prefixes or suffixes), or
    None. Lateral segments need a side; midline ones take none."""
    for side, core in ((*_split_side(label),), (None, label.strip())):
        parts = [p for p in re.split(r"[._\- ]+", core) if p]
        candidates = [core.replace(".", "").replace("_", ""), *parts]
        for cand in candidates:
            for pattern, seg in _COMPILED:
                if pattern.match(cand):
                    if seg.endswith("_s"):
                        if side is None:
                            break
                        return LabelGuess(label, side, core, seg[:-1] + side)
                    return LabelGuess(
                        label, None if seg in ("pelvis", "head", "thorax") else side, core, seg
                    )
    side, core = _split_side(label)
    return LabelGuess(label, side, core, None)


def distance_spread(X: FloatArray, max_frames: int = 400) -> FloatArray:
    """(M, M) standard deviation over frames of every pair's distance [m] (NaN when two
    markers are never seen together in 10 frames); X (N, M, 3), a subsample of frames."""
    n = X.shape[0]
    idx = np.linspace(0, n - 1, min(n, max_frames)).round().astype(int)
    Y = X[idx]
    d = np.linalg.norm(Y[:, :, None, :] - Y[:, None, :, :], axis=3)  # (F, M, M)
    ok = np.isfinite(d)
    count = ok.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(ok, d, 0.0).sum(axis=0) / count
        var = np.where(ok, (d - mean[None]) ** 2, 0.0).sum(axis=0) / count
    out = np.sqrt(var)
    out[count < 10] = np.nan
    return np.asarray(out)


@dataclass(frozen=True)
class AutoReport:
    """How each marker was placed: ``labels`` (from its label), ``clusters`` (moved with
    that segment's markers: label unknown, or its label's segment contradicted), and
    ``left_out`` (neither)."""

    labels: dict[str, str]
    clusters: dict[str, str]
    left_out: tuple[str, ...]

    def lines(self) -> list[str]:
        by_seg: dict[str, list[str]] = {}
        for name, seg in {**self.labels, **self.clusters}.items():
            mark = "*" if name in self.clusters else ""
            by_seg.setdefault(seg, []).append(name + mark)
        out = [f"{seg}: {', '.join(names)}" for seg, names in sorted(by_seg.items())]
        if self.left_out:
            out.append(f"left out (no segment found): {', '.join(self.left_out)}")
        return out


def auto_markerset(
    names: Sequence[str], X: FloatArray, name: str = "auto"
) -> tuple[MarkerSet, AutoReport]:
    """A marker set for ``names`` from their labels and motion X (N, M, 3) [m]."""
    guesses = [classify_label(n) for n in names]
    seg = {g.label: g.segment for g in guesses if g.segment is not None}
    spread = distance_spread(np.asarray(X, dtype=float))
    index = {n: i for i, n in enumerate(names)}

    def mates_spread(marker: str, segment: str) -> float:
        others = [index[o] for o, s in seg.items() if s == segment and o != marker]
        vals = spread[index[marker], others] if others else np.array([])
        vals = vals[np.isfinite(vals)]
        return float(np.median(vals)) if vals.size else np.nan

    clusters: dict[str, str] = {}
    segments = sorted(set(seg.values()))
    # a labelled marker that does not move with its segment but with another: moved
    for marker, s in list(seg.items()):
        own = mates_spread(marker, s)
        if np.isfinite(own) and own > 2.5 * RIGID_SPREAD_M:
            best = min(
                segments,
                key=lambda t: (
                    np.inf if t == s else np.nan_to_num(mates_spread(marker, t), nan=np.inf)
                ),
            )
            if mates_spread(marker, best) <= RIGID_SPREAD_M:
                seg[marker] = best
                clusters[marker] = best
    # an unlabelled marker joins the segment it moves rigidly with
    left_out = []
    for g in guesses:
        if g.segment is not None:
            continue
        scores = {t: mates_spread(g.label, t) for t in segments}
        finite = {t: v for t, v in scores.items() if np.isfinite(v)}
        if finite and min(finite.values()) <= RIGID_SPREAD_M:
            best = min(finite, key=lambda t: finite[t])
            seg[g.label] = best
            clusters[g.label] = best
        else:
            left_out.append(g.label)
    markers = []
    for n in names:
        if n not in seg:
            continue
        s = seg[n]
        off = _offset(n, s)
        markers.append(MarkerSpec(n, s, (float(off[0]), float(off[1]), float(off[2])), 1.0))
    ms = MarkerSet(
        name=name,
        markers=tuple(markers),
        reference_height_m=1.75,
        description="assigned automatically from the labels and the motion",
        coordinate_tasks={
            f"{c}_{s}": (0.0, 1000.0) for c in ("subtalar_angle", "mtp_angle") for s in ("r", "l")
        },
    )
    labels = {g.label: g.segment for g in guesses if g.segment is not None}
    report = AutoReport(
        {n: s for n, s in labels.items() if n not in clusters}, clusters, tuple(left_out)
    )
    return ms, report


def _offset(label: str, segment: str) -> FloatArray:
    """A starting offset: the landmark's place when the label names a known one, else the
    segment's typical marker place; y mirrored for the right side."""
    side, core = _split_side(label)
    parts = [p for p in re.split(r"[._\- ]+", core) if p]
    off = None
    for cand in [core.replace(".", "").replace("_", ""), *parts]:
        for pattern, value in _LANDMARK_RE:
            if pattern.match(cand):
                off = np.array(value, dtype=float)
                break
        if off is not None:
            break
    if off is None:
        generic = segment[:-1] + "s" if segment.endswith(("_r", "_l")) else segment
        off = np.array(_TYPICAL[generic], dtype=float)
    if segment.endswith("_r") or (not segment.endswith("_l") and side == "r"):
        off[1] = -off[1]
    return off


def yaml_template(names: Sequence[str], ms: MarkerSet | None = None) -> str:
    """A marker-set YAML for ``names``: the segments found (``?`` where none was), offsets
    as starting guesses (registration on a static trial replaces them)."""
    known = {m.name: m for m in ms.markers} if ms is not None else {}
    lines = ["name: my_markers", "reference_height_m: 1.75", "markers:"]
    for n in names:
        key = yaml.safe_dump(n).strip().removesuffix("...").strip()
        if n in known:
            off = ", ".join(f"{v:.3g}" for v in known[n].offset)
            lines.append(f"  {key}: {{segment: {known[n].segment}, offset: [{off}]}}")
        else:
            lines.append(f'  {key}: {{segment: "?", offset: [0, 0, 0]}}  # pelvis, thigh_r, ...')
    return "\n".join(lines) + "\n"


def require_lower_limbs(ms: MarkerSet, present: Sequence[str], where: str) -> None:
    """Refuse a set that leaves a lower-limb segment without a marker in the trial: the
    reconstruction would exit without hip, knee or ankle angles."""
    have = {m.segment for m in ms.markers if m.name in set(present)}
    missing = [s for s in LOWER_LIMB if s not in have]
    if missing:
        raise DataError(
            f"{where}: no marker of the trial could be placed on {', '.join(missing)}, so "
            f"there would be no hip, knee or ankle angles. The trial's markers: "
            f"{', '.join(present)}. Write a marker set for them and pass --markerset FILE; "
            "this YAML (the segments found so far) is a start:\n" + yaml_template(present, ms)
        )
