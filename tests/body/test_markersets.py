"""Marker set presets and the YAML format."""

from __future__ import annotations

from pathlib import Path

import pytest

from mocapkit.body.human_model import build_human_model
from mocapkit.body.markersets import (
    available_markersets,
    guess_markerset,
    load_markerset,
    markerset_from_dict,
    save_markerset,
)
from mocapkit.errors import ConfigError, FileFormatError


def test_presets_load_and_name_model_segments() -> None:
    segments = set(build_human_model().segments)
    for name in ("gait2392", "cmu41", "walking2"):
        assert name in available_markersets()
        ms = load_markerset(name)
        assert {m.segment for m in ms.markers} <= segments, name
        assert all(c.segment in segments for c in ms.joint_centres)


def test_yaml_round_trip(tmp_path: Path) -> None:
    ms = load_markerset("gait2392")
    back = load_markerset(save_markerset(ms, tmp_path / "set.yaml"))
    assert back.names == ms.names
    assert back.spec("R.ASIS").weight == 10.0
    assert back.static_weights == ms.static_weights
    assert back.paper_grouping() == (("R.Acromium", "L.Wrist.Lat"), ("L.Elbow", "R.Wrist.Lat"))


def test_matching_is_case_insensitive_and_reports() -> None:
    ms = load_markerset("gait2392")
    match = ms.match(["r.asis", "L.ASIS", "Extra"])
    assert match.index == {"R.ASIS": 0, "L.ASIS": 1}
    assert match.extra == ("Extra",)
    assert "V.Sacral" in match.missing
    best, _m = guess_markerset(["LFHD", "RFHD", "C7", "LKNE", "RKNE", "LANK"])
    assert best.name == "cmu41"


def test_bad_yaml(tmp_path: Path) -> None:
    with pytest.raises(FileFormatError, match="marker 'A' needs a 'segment'"):
        markerset_from_dict({"markers": {"A": {"offset": [0, 0, 0]}}})
    with pytest.raises(FileFormatError, match="not a plausible marker offset in metres"):
        markerset_from_dict({"markers": {"A": {"segment": "pelvis", "offset": [100, 0, 0]}}})
    with pytest.raises(
        FileFormatError,
        match="scaling\\[0\\] needs 'segments' and 'pairs' of known markers \\(unknown: B\\)",
    ):
        markerset_from_dict(
            {
                "markers": {"A": {"segment": "pelvis"}},
                "scaling": [{"segments": ["pelvis"], "pairs": [["A", "B"]]}],
            }
        )
    p = tmp_path / "x.yaml"
    p.write_text("markers: [unclosed")
    with pytest.raises(FileFormatError, match="invalid YAML"):
        load_markerset(p)
    with pytest.raises(ConfigError, match="not a preset"):
        load_markerset("nope")
    with pytest.raises(ConfigError, match="lacks the roles right_shoulder"):
        markerset_from_dict({"markers": {"A": {"segment": "pelvis"}}}).paper_grouping()
