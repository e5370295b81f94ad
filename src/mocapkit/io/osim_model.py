"""mocapkit's scaled human model as an OpenSim model file (``.osim``, OpenSim 4 format).

What a user needs to open a reconstruction in OpenSim: every segment a ``Body`` (mass,
centre of mass, inertia), every anatomical joint a ``CustomJoint`` whose rotations are
the model's own DOFs (same names, same axes, same order), every registered marker a
``Marker``, so that the ``.mot`` that ``markers reconstruct`` writes (which carries the
model's DOF columns beside OpenSim's coordinate names) poses it exactly
(tests/io/test_opensim_round_trips.py: OpenSim reproduces our model markers to 1e-6 m).

Frames: OpenSim's ground is y-up (x forward, y up, z right); every body frame is our
segment frame with its axes renamed the same way (``v_os = C v_ours``,
:data:`mocapkit.markers.coordinates.Z_UP_TO_OPENSIM`), so at the neutral pose all bodies
are parallel to the ground as in our model. The pelvis joint is gait2392's: body-fixed
Z-X-Y rotations ``pelvis_tilt``, ``pelvis_list``, ``pelvis_rotation`` then translations
``pelvis_tx, ty, tz`` in the ground, the columns our ``.mot`` writes. Joints with one or two
DOFs fill their remaining rotation axes with constant-zero functions (OpenSim needs three
independent axes). No muscles, no geometry meshes (OpenSim draws the frames).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit._validate import FloatArray
from mocapkit.body.human_model import HumanModel
from mocapkit.markers.coordinates import PELVIS_COLUMNS, Z_UP_TO_OPENSIM

_C = Z_UP_TO_OPENSIM
_PELVIS_ROTATIONS = (("pelvis_tilt", (0.0, 0.0, 1.0)), ("pelvis_list", (1.0, 0.0, 0.0)),
                     ("pelvis_rotation", (0.0, 1.0, 0.0)))  # fmt: skip
_UNIT = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


def _vec(v: Any) -> str:
    return " ".join(f"{float(x):.12g}" for x in np.asarray(v, dtype=float).reshape(-1))


def _sub(parent: ET.Element, tag: str, text: str | None = None, **attrib: str) -> ET.Element:
    el = ET.SubElement(parent, tag, attrib)
    if text is not None:
        el.text = text
    return el


def _coordinate(parent: ET.Element, name: str, lo: float, hi: float) -> None:
    c = _sub(parent, "Coordinate", name=name)
    _sub(c, "default_value", "0")
    _sub(c, "default_speed_value", "0")
    _sub(c, "range", _vec([lo, hi]))
    _sub(c, "clamped", "false")
    _sub(c, "locked", "false")


def _axis_fill(axes: list[FloatArray]) -> list[FloatArray]:
    """The given rotation axes completed to three independent ones (unit axes that are
    least aligned with those already there)."""
    out = [a / np.linalg.norm(a) for a in axes]
    for e in _UNIT:
        if len(out) == 3:
            break
        cand = np.asarray(e)
        M = np.array([*out, cand])
        if np.linalg.matrix_rank(M, tol=1e-6) == len(out) + 1:
            out.append(cand)
    return out


def _transform_axis(parent: ET.Element, name: str, axis: Any, coordinate: str | None) -> None:
    ta = _sub(parent, "TransformAxis", name=name)
    _sub(ta, "coordinates", coordinate or "")
    _sub(ta, "axis", _vec(axis))
    if coordinate:
        fn = _sub(ta, "LinearFunction", name="function")
        _sub(fn, "coefficients", "1 0")
    else:
        fn = _sub(ta, "Constant", name="function")
        _sub(fn, "value", "0")


def _joint(
    joints: ET.Element,
    name: str,
    parent_path: str,
    child_path: str,
    position_os: FloatArray,
    rotations: list[tuple[str, FloatArray, float, float]],
    translations: list[tuple[str, float, float]] | None = None,
) -> None:
    """A CustomJoint: rotations (name, axis in the parent frame [OpenSim axes], lo, hi)
    then translations (coordinate name, lo, hi) along the parent's x, y, z."""
    j = _sub(joints, "CustomJoint", name=name)
    _sub(j, "socket_parent_frame", f"{name}_parent_offset")
    _sub(j, "socket_child_frame", child_path)
    coords = _sub(j, "coordinates")
    for cname, _, lo, hi in rotations:
        _coordinate(coords, cname, lo, hi)
    for cname, lo, hi in translations or []:
        _coordinate(coords, cname, lo, hi)
    frames = _sub(j, "frames")
    off = _sub(frames, "PhysicalOffsetFrame", name=f"{name}_parent_offset")
    _sub(off, "socket_parent", parent_path)
    _sub(off, "translation", _vec(position_os))
    _sub(off, "orientation", "0 0 0")
    st = _sub(j, "SpatialTransform")
    axes = _axis_fill([np.asarray(a, dtype=float) for _, a, _, _ in rotations])
    for k in range(3):
        rname = rotations[k][0] if k < len(rotations) else None
        _transform_axis(st, f"rotation{k + 1}", axes[k], rname)
    for k in range(3):
        tname = translations[k][0] if translations else None
        _transform_axis(st, f"translation{k + 1}", _UNIT[k], tname)


def osim_document(human: HumanModel, name: str = "mocapkit_subject") -> ET.ElementTree:
    """The ``.osim`` document of a scaled model (its markers included)."""
    model = human.model
    doc = ET.Element("OpenSimDocument", Version="40000")
    m = _sub(doc, "Model", name=name)
    _sub(m, "Ground", name="ground")
    gravity = _C @ np.asarray(model.gravity.linear, dtype=float)
    _sub(m, "gravity", _vec(gravity))
    _sub(m, "credits", "mocapkit: scaled from marker data (body/human_model.py)")
    _sub(m, "length_units", "meters")
    _sub(m, "force_units", "N")
    bodies = _sub(_sub(m, "BodySet", name="bodyset"), "objects")
    for seg, jid in human.segment_joint.items():
        inertia = model.inertias[jid]
        b = _sub(bodies, "Body", name=seg)
        _sub(b, "mass", f"{float(inertia.mass):.12g}")
        _sub(b, "mass_center", _vec(_C @ np.asarray(inertia.lever)))
        I_os = _C @ np.asarray(inertia.inertia) @ _C.T
        _sub(b, "inertia", _vec([I_os[0, 0], I_os[1, 1], I_os[2, 2], I_os[0, 1], I_os[0, 2],
                                 I_os[1, 2]]))  # fmt: skip
    joints = _sub(_sub(m, "JointSet", name="jointset"), "objects")
    big = 10.0 * np.pi
    pelvis_rot = [(n, np.asarray(a), -big, big) for n, a in _PELVIS_ROTATIONS]
    pelvis_tr = [(n, -50.0, 50.0) for n in PELVIS_COLUMNS[:3]]
    _joint(joints, "ground_pelvis", "/ground", "/bodyset/pelvis", np.zeros(3), pelvis_rot,
           pelvis_tr)  # fmt: skip
    lo, hi = human.dof_limits()
    index = {d: i for i, d in enumerate(human.dof_names)}
    for spec in human.joints:
        scale = human.segment_scales.get(spec.parent, 1.0)
        position = _C @ (np.asarray(spec.position, dtype=float) * scale)
        rotations = [
            (d.name, _C @ np.asarray(d.axis, dtype=float), float(lo[index[d.name]]),
             float(hi[index[d.name]]))
            for d in spec.dofs
        ]  # fmt: skip
        _joint(joints, spec.name, f"/bodyset/{spec.parent}", f"/bodyset/{spec.child}",
               position, rotations)  # fmt: skip
    markers = _sub(_sub(m, "MarkerSet", name="markerset"), "objects")
    for mname, (seg, offset) in human.markers.items():
        mk = _sub(markers, "Marker", name=mname)
        _sub(mk, "socket_parent_frame", f"/bodyset/{seg}")
        _sub(mk, "location", _vec(_C @ np.asarray(offset, dtype=float)))
        _sub(mk, "fixed", "true")
    ET.indent(doc, space="\t")
    return ET.ElementTree(doc)


def write_osim(path: str | Path, human: HumanModel, name: str | None = None) -> Path:
    """Write ``human`` (scaled, markers registered) as an OpenSim 4 model file."""
    p = Path(path)
    tree = osim_document(human, name or p.stem)
    tree.write(p, encoding="UTF-8", xml_declaration=True)
    return p
