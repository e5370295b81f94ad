"""Marker subsets for direct marker control, in priority order (the paper's m_1 ... m_n).

The paper groups markers into *independent* subsets: markers on one rigid segment are
coupled, so they should not share a level. Strategies:

- ``paper``: the seed's own grouping — (right shoulder, left wrist), then (left elbow,
  right wrist), taken from the marker set's ``groups.paper`` or its ``roles`` — as the two
  top levels, then every other marker in one level below them: the paper's hierarchy on a
  whole body (its four arm markers alone determine no joint of a body whose pelvis and
  trunk are free: every angle came out NaN);
- ``paper-only``: the paper's two subsets and nothing else (its tai chi experiment, on
  the arms alone); the trunk and legs are then undetermined and left out;
- ``weights`` (reliability): one level per distinct marker weight, heaviest first — the
  marker set's weights say how much a marker can be trusted (OpenSim's gait2392: bony
  landmarks 10, clusters 1, acromion 0.5, head 0.1), so trusted markers are tracked
  exactly and the rest share what is left, least squares within a level (weights scale
  the rows); a set whose markers all weigh the same gives one level;
- ``tree``: level d holds the markers of the segments d joints away from the pelvis, so
  distal markers cannot tilt proximal segments (a foot marker never moves the pelvis);
- ``independent`` (alias ``auto``, the automatic grouping of all markers): level i holds
  the i-th heaviest marker (IK weight, then name) of every segment — the paper's rule that
  rigidly coupled markers never share a level; with skin-marker noise its nearly square
  first level makes the hierarchy fragile (measured in docs/benchmarks.md);
- ``single`` (the default): one level with every marker, least squares weighted by the
  marker weights — the paper's formulation with n = 1 and the posture below;
- a YAML file: ``levels: [[A, B], [C, D, E]]``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import yaml

from mocapkit.body.markersets import MarkerSet
from mocapkit.errors import ConfigError, FileFormatError

Levels = tuple[tuple[str, ...], ...]
STRATEGIES = ("single", "independent", "auto", "tree", "weights", "paper", "paper-only")


def weight_levels(names: Sequence[str], weights: Mapping[str, float]) -> Levels:
    """One level per distinct weight (heaviest first; weight 0 left out)."""
    classes = sorted({weights.get(n, 1.0) for n in names if weights.get(n, 1.0) > 0}, reverse=True)
    return tuple(tuple(n for n in names if weights.get(n, 1.0) == w) for w in classes)


def tree_levels(
    names: Sequence[str],
    segment_of: Mapping[str, str],
    weights: Mapping[str, float],
    segment_depth: Mapping[str, int],
) -> Levels:
    """Level d = markers on segments at depth d of the kinematic tree (weight 0 left out)."""
    by_depth: dict[int, list[str]] = {}
    for n in names:
        if weights.get(n, 1.0) > 0:
            by_depth.setdefault(segment_depth[segment_of[n]], []).append(n)
    return tuple(tuple(by_depth[d]) for d in sorted(by_depth))


def independent_levels(
    names: Sequence[str], segment_of: Mapping[str, str], weights: Mapping[str, float]
) -> Levels:
    """Level i = the i-th heaviest marker of every segment (weight 0 markers left out)."""
    by_segment: dict[str, list[str]] = {}
    for n in names:
        if weights.get(n, 1.0) > 0:
            by_segment.setdefault(segment_of[n], []).append(n)
    for seg in by_segment:
        by_segment[seg].sort(key=lambda n: (-weights.get(n, 1.0), n))
    depth = max((len(v) for v in by_segment.values()), default=0)
    order = list(dict.fromkeys(segment_of[n] for n in names))
    levels = []
    for i in range(depth):
        level = tuple(by_segment[s][i] for s in order if s in by_segment and len(by_segment[s]) > i)
        levels.append(level)
    return tuple(levels)


def make_levels(
    strategy: str,
    names: Sequence[str],
    markerset: MarkerSet,
    segment_of: Mapping[str, str],
    weights: Mapping[str, float],
    segment_depth: Mapping[str, int],
) -> Levels:
    """Priority levels over the tracked ``names`` for a strategy or a YAML file."""
    available = set(names)
    if strategy == "weights":
        return weight_levels(names, weights)
    if strategy == "tree":
        return tree_levels(names, segment_of, weights, segment_depth)
    if strategy in ("independent", "auto"):
        return independent_levels(names, segment_of, weights)
    if strategy == "single":
        return (tuple(n for n in names if weights.get(n, 1.0) > 0),)
    if strategy in ("paper", "paper-only"):
        levels = markerset.paper_grouping()
        if strategy == "paper":
            top = {m for level in levels for m in level}
            rest = tuple(n for n in names if n not in top and weights.get(n, 1.0) > 0)
            levels = (*levels, rest) if rest else levels
    else:
        p = Path(strategy)
        if not p.is_file():
            raise ConfigError(
                f"grouping {strategy!r}: expected {', '.join(STRATEGIES)} or a YAML file"
            )
        try:
            doc = yaml.safe_load(p.read_text())
            levels = tuple(tuple(str(m) for m in level) for level in doc["levels"])
        except (yaml.YAMLError, KeyError, TypeError) as exc:
            raise FileFormatError(f"{p}: expected 'levels: [[marker, ...], ...]' ({exc})") from exc
    missing = [m for level in levels for m in level if m not in available]
    if missing:
        raise ConfigError(
            f"grouping {strategy!r} needs markers {', '.join(missing)}, which the trial does not "
            "track (missing from the trial or the static trial); pick another grouping"
        )
    return levels
