"""Live ROS 2 topics without a ROS install: CDR messages over Zenoh in rmw_zenoh's format
(``eclipse-zenoh`` for the transport, ``rosbags`` for CDR and the type hashes).

A ROS 2 machine running ``rmw_zenoh_cpp`` (the Zenoh router ``rmw_zenohd`` at
``tcp/HOST:7447``) receives what :class:`Ros2ZenohPublisher` puts on

    <domain id>/<topic without its leading slash>/<type, DDS-mangled>/<RIHS01 type hash>

e.g. ``0/mocapkit/joint_states/sensor_msgs::msg::dds_::JointState_/RIHS01_a13e...``, with
rmw_zenoh's attachment (sequence number, source timestamp [ns], a 16-byte publisher
GID). ``ros2 topic echo /mocapkit/joint_states sensor_msgs/msg/JointState`` prints it.

The ROS graph: rmw_zenoh learns of nodes, publishers and subscriptions from Zenoh
liveliness tokens (``ros2 node list``, ``ros2 topic list``). The publisher declares them
as rmw_zenoh does (its ``liveliness_utils.cpp``, read at its 2024-10 state)::

    @ros2_lv/<domain>/<zid>/<node id>/<entity id>/<NN|MP|MS>/<enclave>/<namespace>/<node>
        [/<topic>/<type, DDS-mangled>/<type hash>/<QoS>]

with ``/`` inside names written ``%`` (the root namespace and enclave are ``%``) and the
default QoS as ``::,:,:,:,,`` (every policy at its default). The node is ``/mocapkit``.
(The Zenoh id is written as Zenoh prints it; rmw_zenoh drops leading zeros per byte, which
only matters for telling our own entities apart.)

The live session (``mocapkit teleop run --ros2-zenoh tcp/127.0.0.1:7447``) publishes
``/mocapkit/joint_states`` (the body model's joint angles, ``sensor_msgs/JointState``) and
``/mocapkit/robot/joint_states`` (the robot's retargeted joints) every frame.
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from mocapkit.errors import MissingDependencyError

TYPESTORE = "ROS2_JAZZY"
ADMIN_SPACE = "@ros2_lv"  # rmw_zenoh's liveliness tokens
NODE_NAME = "mocapkit"
DEFAULT_QOS = "::,:,:,:,,"  # rmw_zenoh's QoS key with every policy at its default


def _deps() -> tuple[Any, Any, Any]:
    try:
        import zenoh
        import zenoh.ext as zext
        from rosbags.typesys import Stores, get_typestore
    except ImportError as exc:
        raise MissingDependencyError(
            f"live ROS 2 over Zenoh needs eclipse-zenoh and rosbags ({exc}): "
            "pip install 'mocapkit[ros]'"
        ) from exc
    return zenoh, zext, get_typestore(getattr(Stores, TYPESTORE))


def key_expr(domain_id: int, topic: str, type_name: str, type_hash: str) -> str:
    """rmw_zenoh's key expression of a topic (module docstring)."""
    pkg, kind, name = type_name.split("/")
    return f"{domain_id}/{topic.strip('/')}/{pkg}::{kind}::dds_::{name}_/{type_hash}"


class Ros2ZenohPublisher:
    """Publishes ROS 2 messages over Zenoh (module docstring).

    Args:
        connect: Zenoh endpoints to connect to (the ROS machine's router, e.g.
            ``tcp/127.0.0.1:7447``); empty: a peer found by Zenoh's own scouting.
        domain_id: ``ROS_DOMAIN_ID`` (default: the environment's, else 0).
    """

    def __init__(self, connect: Sequence[str] = (), domain_id: int | None = None) -> None:
        zenoh, self._zext, self.types = _deps()
        self.domain_id = (
            int(os.environ.get("ROS_DOMAIN_ID", "0")) if domain_id is None else domain_id
        )
        conf = zenoh.Config()
        conf.insert_json5("mode", '"peer"')
        if connect:
            conf.insert_json5("connect/endpoints", str(list(connect)).replace("'", '"'))
        self.session = zenoh.open(conf)
        self._pubs: dict[str, Any] = {}
        self._subs: list[Any] = []
        self._tokens: list[Any] = []
        self._zid = str(self.session.info.zid())
        self._node = f"{self.domain_id}/{self._zid}/0"
        self._entities = 0
        self._token(f"{self._node}/0/NN/%/%/{NODE_NAME}")
        self._seq: dict[str, int] = {}
        self.gid = list(os.urandom(16))
        self.published = 0

    def _token(self, rest: str) -> None:
        self._tokens.append(self.session.liveliness().declare_token(f"{ADMIN_SPACE}/{rest}"))

    def _entity_token(self, kind: str, topic: str, type_name: str, type_hash: str) -> None:
        """A publisher's (``MP``) or subscription's (``MS``) graph token (module docstring)."""
        self._entities += 1
        pkg, sub, name = type_name.split("/")
        mangled = "/" + topic.strip("/")
        self._token(
            f"{self._node}/{self._entities}/{kind}/%/%/{NODE_NAME}/{mangled.replace('/', '%')}"
            f"/{pkg}::{sub}::dds_::{name}_/{type_hash}/{DEFAULT_QOS}"
        )

    def _publisher(self, topic: str, type_name: str) -> Any:
        type_hash = self.types.hash_rihs01(type_name)
        key = key_expr(self.domain_id, topic, type_name, type_hash)
        if key not in self._pubs:
            self._pubs[key] = self.session.declare_publisher(key)
            self._entity_token("MP", topic, type_name, type_hash)
            self._seq[key] = 0
        return key

    def publish(self, topic: str, type_name: str, msg: Any) -> str:
        """Serialise ``msg`` (a rosbags message of ``type_name``) as CDR and put it on the
        topic's key expression; returns the key."""
        z = self._zext
        key = self._publisher(topic, type_name)
        self._seq[key] += 1
        data = bytes(self.types.serialize_cdr(msg, type_name))
        att = z.z_serialize((z.Int64(self._seq[key]), z.Int64(time.time_ns()),
                             [z.UInt8(b) for b in self.gid]))  # fmt: skip
        self._pubs[key].put(data, attachment=att)
        self.published += 1
        return key

    def joint_state(
        self, topic: str, names: Sequence[str], positions: Sequence[float], t_ns: int | None = None
    ) -> str:
        """A ``sensor_msgs/JointState`` (positions [rad]; velocity and effort empty)."""
        t_ns = time.time_ns() if t_ns is None else t_ns
        T = self.types.types
        header = T["std_msgs/msg/Header"](
            stamp=T["builtin_interfaces/msg/Time"](sec=t_ns // 10**9, nanosec=t_ns % 10**9),
            frame_id="",
        )
        msg = T["sensor_msgs/msg/JointState"](
            header=header, name=list(names), position=np.asarray(positions, dtype=np.float64),
            velocity=np.zeros(0), effort=np.zeros(0),
        )  # fmt: skip
        return self.publish(topic, "sensor_msgs/msg/JointState", msg)

    def pose_stamped(
        self, topic: str, frame_id: str, pos: Any, quat_wxyz: Any, t_ns: int | None = None,
    ) -> str:  # fmt: skip
        """A ``geometry_msgs/PoseStamped`` (position [m], orientation from ``[w, x, y, z]``)."""
        t_ns = time.time_ns() if t_ns is None else t_ns
        T = self.types.types
        header = T["std_msgs/msg/Header"](
            stamp=T["builtin_interfaces/msg/Time"](sec=t_ns // 10**9, nanosec=t_ns % 10**9),
            frame_id=frame_id,
        )
        w, x, y, z = (float(v) for v in quat_wxyz)
        px, py, pz = (float(v) for v in pos)
        pose = T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=px, y=py, z=pz),
            orientation=T["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w),
        )
        msg = T["geometry_msgs/msg/PoseStamped"](header=header, pose=pose)
        return self.publish(topic, "geometry_msgs/msg/PoseStamped", msg)

    def float64_array(self, topic: str, values: Sequence[float]) -> str:
        """A ``std_msgs/Float64MultiArray`` (no layout): what ros2_control's forward command
        controllers take on ``/<controller>/commands``."""
        T = self.types.types
        layout = T["std_msgs/msg/MultiArrayLayout"](dim=[], data_offset=0)
        msg = T["std_msgs/msg/Float64MultiArray"](
            layout=layout, data=np.asarray(values, dtype=np.float64)
        )
        return self.publish(topic, "std_msgs/msg/Float64MultiArray", msg)

    def subscribe(self, topic: str, type_name: str, callback: Any) -> Any:
        """Call ``callback(msg)`` with every message of ``type_name`` on ``topic`` (any
        type hash: a peer on another ROS distribution still matches); a payload that does
        not decode calls ``callback(None)``. Runs on Zenoh's thread: keep it short."""
        pkg, kind, name = type_name.split("/")
        key = f"{self.domain_id}/{topic.strip('/')}/{pkg}::{kind}::dds_::{name}_/*"

        def on_sample(sample: Any) -> None:
            try:
                msg = self.types.deserialize_cdr(bytes(sample.payload.to_bytes()), type_name)
            except Exception:  # garbage from the network must not reach the session
                msg = None
            callback(msg)

        sub = self.session.declare_subscriber(key, on_sample)
        self._subs.append(sub)
        self._entity_token("MS", topic, type_name, self.types.hash_rihs01(type_name))
        return sub

    def close(self) -> None:
        for token in self._tokens:
            token.undeclare()
        for sub in self._subs:
            sub.undeclare()
        for pub in self._pubs.values():
            pub.undeclare()
        self.session.close()

    def __enter__(self) -> Ros2ZenohPublisher:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
