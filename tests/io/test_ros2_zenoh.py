"""Live ROS 2 over Zenoh: a Zenoh subscriber on rmw_zenoh's key expression (as a ROS 2
node on rmw_zenoh subscribes) receives mocapkit's JointState and decodes the CDR."""

from __future__ import annotations

import socket
import threading
import time

import numpy as np
import pytest

zenoh = pytest.importorskip("zenoh", reason="live ROS 2 needs eclipse-zenoh ('mocapkit[ros]')")
pytest.importorskip("rosbags")

from mocapkit.io.ros2_zenoh import Ros2ZenohPublisher, key_expr  # noqa: E402

pytestmark = pytest.mark.realtime


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_key_expression_is_rmw_zenohs() -> None:
    k = key_expr(0, "/mocapkit/joint_states", "sensor_msgs/msg/JointState", "RIHS01_ab")
    assert k == "0/mocapkit/joint_states/sensor_msgs::msg::dds_::JointState_/RIHS01_ab"


def test_a_zenoh_subscriber_decodes_the_joint_states() -> None:
    import zenoh.ext as zext
    from rosbags.typesys import Stores, get_typestore

    types = get_typestore(Stores.ROS2_JAZZY)
    port = _free_port()
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("listen/endpoints", f'["tcp/127.0.0.1:{port}"]')
    conf.insert_json5("scouting/multicast/enabled", "false")
    got: list = []
    done = threading.Event()
    h = types.hash_rihs01("sensor_msgs/msg/JointState")
    with zenoh.open(conf) as sub_session:

        def on_sample(sample) -> None:
            got.append((str(sample.key_expr), bytes(sample.payload.to_bytes()),
                        sample.attachment))  # fmt: skip
            if len(got) >= 3:
                done.set()

        sub = sub_session.declare_subscriber(f"0/**/{h}", on_sample)
        with Ros2ZenohPublisher(connect=[f"tcp/127.0.0.1:{port}"], domain_id=0) as pub:
            time.sleep(0.5)  # the sessions meet
            for k in range(20):
                pub.joint_state("/mocapkit/joint_states", ["hip", "knee"], [0.1 * k, -0.5])
                time.sleep(0.02)
                if done.is_set():
                    break
            assert done.wait(5.0), "nothing arrived"
        sub.undeclare()
    key, payload, att = got[-1]
    assert key == f"0/mocapkit/joint_states/sensor_msgs::msg::dds_::JointState_/{h}"
    msg = types.deserialize_cdr(payload, "sensor_msgs/msg/JointState")
    assert list(msg.name) == ["hip", "knee"]
    assert msg.position[1] == -0.5
    assert msg.header.stamp.sec > 1_600_000_000  # wall clock
    seq, t_ns, gid = zext.z_deserialize(tuple[zext.Int64, zext.Int64, list[zext.UInt8]], att)
    assert int(seq) >= 3
    assert int(t_ns) > 1_600_000_000 * 10**9
    assert len(gid) == 16
    seqs = [int(zext.z_deserialize(tuple[zext.Int64, zext.Int64, list[zext.UInt8]], a)[0])
            for _, _, a in got]  # fmt: skip
    assert np.all(np.diff(seqs) == 1)
