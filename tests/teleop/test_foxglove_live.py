"""The live Foxglove server (foxglove-sdk) over loopback: a WebSocket client subscribes as
Foxglove does and decodes what arrives; a client that sends garbage does not stop it."""

from __future__ import annotations

import asyncio
import base64
import contextlib
import json
import struct

import numpy as np
import pytest

pytest.importorskip("foxglove", reason="the live Foxglove server needs foxglove-sdk (viz extra)")
websockets = pytest.importorskip("websockets")

from mocapkit.teleop.foxglove_live import FoxgloveLive  # noqa: E402

SNAP = {
    "state": "engaged",
    "segments": [
        {"name": "torso", "start": [0.1, 0.2, 1.0], "quat": [1.0, 0.0, 0.0, 0.0]},
        {"name": "humerus_r", "start": [0.1, -0.2, 1.4], "quat": [0.0, 1.0, 0.0, 0.0]},
    ],
    "robot_joints_deg": {"shoulder": 90.0, "elbow": -45.0},
    "safety": {"robot_gate": "SYNCED"},
    "latency_ms": {"p50": 1.5, "p99": 3.0},
    "packet_loss": 0.0,
    "message": "engage: engaged",
}
SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]


async def _receive(url: str, topics: tuple[str, ...], want: int = 3) -> dict[str, list]:
    """Subscribe to ``topics`` and collect ``want`` messages of each: {topic: [...]}."""
    async with websockets.connect(url, subprotocols=SUBPROTOCOLS) as ws:
        channels: dict[int, dict] = {}
        while not set(topics) <= {c["topic"] for c in channels.values()}:
            msg = json.loads(await asyncio.wait_for(ws.recv(), 5))
            if msg["op"] == "advertise":
                channels.update({c["id"]: c for c in msg["channels"]})
        wanted = [c for c in channels.values() if c["topic"] in topics]
        subs = [{"id": i, "channelId": c["id"]} for i, c in enumerate(wanted)]
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
        by_sub = {s["id"]: channels[s["channelId"]] for s in subs}
        got: dict[str, list] = {t: [] for t in topics}
        while min(len(v) for v in got.values()) < want:
            data = await asyncio.wait_for(ws.recv(), 5)
            if isinstance(data, str):
                continue
            op, sub, t_ns = struct.unpack_from("<BIQ", data)
            assert op == 1  # message data
            got[by_sub[sub]["topic"]].append((t_ns, data[13:], by_sub[sub]))
        return got


def test_a_client_receives_the_body_the_joints_and_the_state() -> None:
    with FoxgloveLive(lambda: SNAP, port=0).start() as fl:
        got = asyncio.run(_receive(fl.url, ("/body/tf", "/robot/joints", "/session/state")))
    t_ns, payload, _ = got["/session/state"][0]
    assert t_ns > 1_600_000_000 * 10**9  # wall clock, not 1970
    state = json.loads(payload)
    assert state["state"] == "engaged"
    assert state["latency_ms"]["p99"] == 3.0
    joints = json.loads(got["/robot/joints"][0][1])
    assert joints["names"] == ["shoulder", "elbow"]
    assert joints["positions_rad"] == pytest.approx([1.5707963, -0.7853982])
    _, tf_bytes, tf_chan = got["/body/tf"][0]
    assert tf_chan["schemaName"] == "foxglove.FrameTransforms"
    pb = pytest.importorskip("google.protobuf")
    del pb
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    fds = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(tf_chan["schema"]))
    pool = descriptor_pool.DescriptorPool()
    for f in fds.file:
        pool.Add(f)
    cls = message_factory.GetMessageClass(pool.FindMessageTypeByName("foxglove.FrameTransforms"))
    tfs = cls.FromString(tf_bytes).transforms
    assert [t.child_frame_id for t in tfs] == ["torso", "humerus_r"]
    assert tfs[1].parent_frame_id == "world"
    assert (tfs[1].translation.x, tfs[1].translation.y, tfs[1].translation.z) == (0.1, -0.2, 1.4)
    assert tfs[1].rotation.x == 1.0


def test_garbage_from_a_client_does_not_stop_the_server() -> None:
    async def garbage(url: str) -> None:
        async with websockets.connect(url, subprotocols=SUBPROTOCOLS) as ws:
            await ws.send("{not json")
            await ws.send(b"\xff\x00\x01garbage")
            await ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 1}]}))
            # the server may close this client (its right) or ignore it
            with contextlib.suppress(TimeoutError, websockets.ConnectionClosed):
                await asyncio.wait_for(ws.recv(), 0.5)

    with FoxgloveLive(lambda: SNAP, port=0).start() as fl:
        asyncio.run(garbage(fl.url))
        n = fl.published
        got = asyncio.run(_receive(fl.url, ("/session/state",)))
        assert fl.published > n  # still publishing
    assert json.loads(got["/session/state"][-1][1])["state"] == "engaged"


def test_a_humanoid_is_published_as_its_urdf_and_link_frames() -> None:
    """With a humanoid, /robot/tf places every URDF link by forward kinematics at the
    reported joints, and /robot_description carries the URDF's text."""
    pytest.importorskip("pinocchio")
    pytest.importorskip("google.protobuf")
    from mocapkit.retarget.robot_model import build_humanoid
    from mocapkit.retarget.robot_spec import load_robot_spec

    robot = build_humanoid(load_robot_spec("g1"))
    snap = dict(SNAP)
    snap["robot_joints_deg"] = {n: 0.0 for n in robot.iq_names}
    snap["robot_joints_deg"]["right_elbow_joint"] = 90.0
    with FoxgloveLive(lambda: snap, port=0, robot=robot).start() as fl:
        got = asyncio.run(_receive(fl.url, ("/robot/tf", "/robot_description"), want=1))
    _, payload, chan = got["/robot_description"][0]
    assert chan["schemaName"] == "std_msgs/String"
    assert json.loads(payload)["data"].lstrip().startswith("<")
    assert "right_elbow_link" in json.loads(payload)["data"]
    _, tf_bytes, tf_chan = got["/robot/tf"][0]
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    fds = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(tf_chan["schema"]))
    pool = descriptor_pool.DescriptorPool()
    for f in fds.file:
        pool.Add(f)
    cls = message_factory.GetMessageClass(pool.FindMessageTypeByName("foxglove.FrameTransforms"))
    tfs = {t.child_frame_id: t for t in cls.FromString(tf_bytes).transforms}
    assert {"pelvis", "right_elbow_link", "right_wrist_yaw_link"} <= set(tfs)
    assert tfs["pelvis"].translation.z > 0.5  # standing at its reference height
    # the frames follow the joints: bending the elbow by 90 deg moves the wrist, not the
    # elbow (what /robot/tf carries, computed for two elbow angles)
    from mocapkit.teleop.foxglove_live import RobotFrames

    frames = RobotFrames(robot)
    a = {n: (p, q) for n, p, q in frames.links(snap["robot_joints_deg"])}
    bent = dict(snap["robot_joints_deg"], right_elbow_joint=0.0)
    b = {n: (p, q) for n, p, q in frames.links(bent)}
    np.testing.assert_allclose(a["right_elbow_link"][0], b["right_elbow_link"][0], atol=1e-9)
    assert np.linalg.norm(a["right_wrist_yaw_link"][0] - b["right_wrist_yaw_link"][0]) > 0.1
    elbow = tfs["right_elbow_link"].translation
    np.testing.assert_allclose([elbow.x, elbow.y, elbow.z], a["right_elbow_link"][0], atol=1e-6)
