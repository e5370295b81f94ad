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


def listening_peer() -> tuple[object, str]:
    """A Zenoh peer listening on a free loopback port (the ROS machine's rmw_zenohd role),
    without multicast scouting: (session, its endpoint)."""
    port = _free_port()
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("listen/endpoints", f'["tcp/127.0.0.1:{port}"]')
    conf.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(conf), f"tcp/127.0.0.1:{port}"


def test_key_expression_is_rmw_zenohs() -> None:
    k = key_expr(0, "/mocapkit/joint_states", "sensor_msgs/msg/JointState", "RIHS01_ab")
    assert k == "0/mocapkit/joint_states/sensor_msgs::msg::dds_::JointState_/RIHS01_ab"


def test_a_zenoh_subscriber_decodes_the_joint_states() -> None:
    import zenoh.ext as zext
    from rosbags.typesys import Stores, get_typestore

    types = get_typestore(Stores.ROS2_JAZZY)
    sub_session, endpoint = listening_peer()
    got: list = []
    done = threading.Event()
    h = types.hash_rihs01("sensor_msgs/msg/JointState")
    with sub_session:

        def on_sample(sample) -> None:
            got.append((str(sample.key_expr), bytes(sample.payload.to_bytes()),
                        sample.attachment))  # fmt: skip
            if len(got) >= 3:
                done.set()

        sub = sub_session.declare_subscriber(f"0/**/{h}", on_sample)
        with Ros2ZenohPublisher(connect=[endpoint], domain_id=0) as pub:
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


def _split_token(key: str) -> dict[str, str]:
    """A graph token read back as rmw_zenoh's Entity::make reads it."""
    parts = key.split("/")
    names = ["admin", "domain", "zid", "nid", "id", "entity", "enclave", "namespace",
             "node", "topic", "type", "hash", "qos"]  # fmt: skip
    assert all(parts), key  # rmw_zenoh refuses empty parts
    return dict(zip(names, parts, strict=False))


def test_graph_tokens_as_rmw_zenoh_reads_them() -> None:
    """A ROS 2 graph (ros2 node list, ros2 topic list) sees mocapkit's node, its
    publisher and its subscription through liveliness tokens in rmw_zenoh's format."""
    graph, endpoint = listening_peer()
    with graph:
        with Ros2ZenohPublisher(connect=[endpoint], domain_id=7) as pub:
            pub.joint_state("/mocapkit/joint_states", ["hip"], [0.1])
            pub.subscribe("/joint_states", "sensor_msgs/msg/JointState", lambda m: None)
            time.sleep(0.5)
            keys = []
            for reply in graph.liveliness().get("@ros2_lv/7/**", timeout=2.0):
                keys.append(str(reply.ok.key_expr))
        tokens = [_split_token(k) for k in keys]
        node = [t for t in tokens if t["entity"] == "NN"]
        assert len(node) == 1
        assert (node[0]["namespace"], node[0]["node"], node[0]["enclave"]) == ("%", "mocapkit", "%")
        by_kind = {t["entity"]: t for t in tokens if t["entity"] in ("MP", "MS")}
        mp, ms = by_kind["MP"], by_kind["MS"]
        assert mp["topic"] == "%mocapkit%joint_states"
        assert mp["type"] == "sensor_msgs::msg::dds_::JointState_"
        assert mp["hash"].startswith("RIHS01_")
        assert mp["qos"] == "::,:,:,:,,"
        assert ms["topic"] == "%joint_states"
        assert mp["zid"] == ms["zid"] == node[0]["zid"]
        assert mp["nid"] == ms["nid"] == node[0]["nid"]
        assert len({node[0]["id"], mp["id"], ms["id"]}) == 3
        # closing the publisher withdraws its tokens: the graph forgets the node
        time.sleep(0.3)
        left = list(graph.liveliness().get("@ros2_lv/7/**", timeout=1.0))
        assert left == []
