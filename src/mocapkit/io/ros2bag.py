"""ROS 2 bags without a ROS install (``rosbags``, pure Python): what ``ros2 bag play`` and
any rosbag2 reader load.

- :func:`write_imu_bag`: one ``sensor_msgs/msg/Imu`` topic per sensor (``/imu/<name>``:
  angular velocity [rad/s], linear acceleration [m/s^2], and the orientation when given,
  else ``orientation_covariance[0] = -1`` as REP 145 asks for "no orientation");
  magnetometers as ``sensor_msgs/msg/MagneticField`` (``/imu/<name>/mag``, in tesla);
- :func:`write_joint_state_bag`: joint angles as ``sensor_msgs/msg/JointState`` on
  ``/joint_states`` [rad], with ``tf2_msgs/msg/TFMessage`` on ``/tf`` for segment
  orientations when given (``parent`` -> segment frames, rotation only).

Stamps: the recording's time plus ``t0_ns`` (default: now, as a recorder would stamp
it); quaternions leave as ROS's ``x, y, z, w``; storage is rosbag2's SQLite3 (version 8)
or MCAP. Needs ``pip install 'mocapkit[ros]'``.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from mocapkit.errors import ConfigError, MissingDependencyError
from mocapkit.series import ImuRecording, JointAngleSeries, OrientationSeries

DISTRO = "ROS2_HUMBLE"


def _rosbags() -> tuple[Any, Any, Any]:
    try:
        from rosbags.rosbag2 import StoragePlugin, Writer
        from rosbags.typesys import Stores, get_typestore
    except ImportError as exc:
        raise MissingDependencyError(
            "ROS 2 bags need rosbags: pip install 'mocapkit[ros]'"
        ) from exc
    return Writer, StoragePlugin, get_typestore(getattr(Stores, DISTRO))


def _stamp(ts: Any, t_ns: int) -> Any:
    Time = ts.types["builtin_interfaces/msg/Time"]
    return Time(sec=int(t_ns // 1_000_000_000), nanosec=int(t_ns % 1_000_000_000))


def _header(ts: Any, t_ns: int, frame: str) -> Any:
    Header = ts.types["std_msgs/msg/Header"]
    return Header(stamp=_stamp(ts, t_ns), frame_id=frame)


def _vec(ts: Any, v: Any) -> Any:
    return ts.types["geometry_msgs/msg/Vector3"](x=float(v[0]), y=float(v[1]), z=float(v[2]))


def _quat(ts: Any, q: Any) -> Any:  # ours [w, x, y, z] -> ROS x, y, z, w
    Q = ts.types["geometry_msgs/msg/Quaternion"]
    return Q(x=float(q[1]), y=float(q[2]), z=float(q[3]), w=float(q[0]))


def _open(path: str | Path, storage: str) -> tuple[Any, Any]:
    Writer, StoragePlugin, ts = _rosbags()
    p = Path(path)
    if p.exists():
        raise ConfigError(f"{p}: already exists; a ROS 2 bag is a new directory (remove it)")
    if storage not in ("sqlite3", "mcap"):
        raise ConfigError(f"storage: expected sqlite3 or mcap, got {storage!r}")
    plugin = StoragePlugin.SQLITE3 if storage == "sqlite3" else StoragePlugin.MCAP
    return Writer(p, version=8, storage_plugin=plugin), ts


def write_imu_bag(
    path: str | Path,
    recordings: Mapping[str, ImuRecording],
    orientations: Mapping[str, OrientationSeries] | None = None,
    t0_ns: int | None = None,
    storage: str = "sqlite3",
) -> Path:
    """Write IMU recordings (and their orientations) as a ROS 2 bag directory."""
    writer, ts = _open(path, storage)
    Imu = ts.types["sensor_msgs/msg/Imu"]
    Mag = ts.types["sensor_msgs/msg/MagneticField"]
    t0 = time.time_ns() if t0_ns is None else t0_ns
    zeros = np.zeros(9)
    no_orientation = np.array([-1.0, 0, 0, 0, 0, 0, 0, 0, 0])
    with writer:
        for name, rec in recordings.items():
            frame = "_".join(name.split())
            topic = f"/imu/{frame}"
            conn = writer.add_connection(topic, Imu.__msgtype__, typestore=ts)
            mag_conn = None
            if rec.mag is not None:
                mag_conn = writer.add_connection(f"{topic}/mag", Mag.__msgtype__, typestore=ts)
            ori = None if orientations is None else orientations.get(name)
            if ori is not None and ori.quat.shape[0] != rec.n_samples:
                raise ConfigError(
                    f"orientations[{name!r}]: {ori.quat.shape[0]} samples for a recording of "
                    f"{rec.n_samples}"
                )
            stamps = t0 + np.round((rec.time - rec.time[0]) * 1e9).astype(np.int64)
            for k in range(rec.n_samples):
                t_ns = int(stamps[k])
                header = _header(ts, t_ns, frame)
                msg = Imu(
                    header=header,
                    orientation=_quat(ts, ori.quat[k] if ori is not None else [1.0, 0, 0, 0]),
                    orientation_covariance=zeros if ori is not None else no_orientation,
                    angular_velocity=_vec(ts, rec.gyr[k]),
                    angular_velocity_covariance=zeros,
                    linear_acceleration=_vec(ts, rec.acc[k]),
                    linear_acceleration_covariance=zeros,
                )
                writer.write(conn, t_ns, ts.serialize_cdr(msg, Imu.__msgtype__))
                if mag_conn is not None and rec.mag is not None and np.isfinite(rec.mag[k]).all():
                    field = Mag(
                        header=header,
                        magnetic_field=_vec(ts, rec.mag[k] * 1e-6),  # uT -> T
                        magnetic_field_covariance=zeros,
                    )
                    writer.write(mag_conn, t_ns, ts.serialize_cdr(field, Mag.__msgtype__))
    return Path(path)


def write_joint_state_bag(
    path: str | Path,
    angles: JointAngleSeries,
    segments: Mapping[str, OrientationSeries] | None = None,
    parent: str = "world",
    t0_ns: int | None = None,
    storage: str = "sqlite3",
) -> Path:
    """Write joint angles (and segment orientations on ``/tf``) as a ROS 2 bag."""
    writer, ts = _open(path, storage)
    JointState = ts.types["sensor_msgs/msg/JointState"]
    TFMessage = ts.types["tf2_msgs/msg/TFMessage"]
    Transform = ts.types["geometry_msgs/msg/Transform"]
    Stamped = ts.types["geometry_msgs/msg/TransformStamped"]
    t0 = time.time_ns() if t0_ns is None else t0_ns
    stamps = t0 + np.round((angles.time - angles.time[0]) * 1e9).astype(np.int64)
    names = list(angles.names)
    with writer:
        conn = writer.add_connection("/joint_states", JointState.__msgtype__, typestore=ts)
        tf_conn = None
        if segments:
            tf_conn = writer.add_connection("/tf", TFMessage.__msgtype__, typestore=ts)
        empty = np.zeros(0)
        for k in range(angles.time.shape[0]):
            t_ns = int(stamps[k])
            msg = JointState(
                header=_header(ts, t_ns, ""),
                name=names,
                position=np.asarray(angles.values[k], dtype=np.float64),
                velocity=empty,
                effort=empty,
            )
            writer.write(conn, t_ns, ts.serialize_cdr(msg, JointState.__msgtype__))
            if tf_conn is not None and segments:
                transforms = [
                    Stamped(
                        header=_header(ts, t_ns, parent),
                        child_frame_id=seg,
                        transform=Transform(
                            translation=_vec(ts, [0.0, 0.0, 0.0]), rotation=_quat(ts, s.quat[k])
                        ),
                    )
                    for seg, s in segments.items()
                ]
                tf = TFMessage(transforms=transforms)
                writer.write(tf_conn, t_ns, ts.serialize_cdr(tf, TFMessage.__msgtype__))
    return Path(path)
