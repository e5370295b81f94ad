"""The motion suit: IMU nodes, the polling hub, the wire protocol, transports, the host
receiver, recording and replay, SlimeVR ingest, and the suit simulator.

Most used entry points::

    from mocapkit.suit import Receiver, ReceiverConfig, UdpTransport, SuitSimulator
    rx = Receiver(UdpTransport.bind("0.0.0.0", 9000)).start()
    for sample in rx.samples(): ...

See ``docs/design/suit.md`` and ``docs/protocol.md``.
"""

from mocapkit.suit.errors import ProtocolError
from mocapkit.suit.fusion import HostFusion
from mocapkit.suit.protocol import Kind, Packet, decode
from mocapkit.suit.receiver import Receiver
from mocapkit.suit.receiver_state import ReceiverConfig
from mocapkit.suit.recording import McapRecorder, ReplayTransport, decode_recording, replay
from mocapkit.suit.samples import ReceiverStats, SensorEvent, SensorStats, SuitSample
from mocapkit.suit.simulator import SuitSimConfig, SuitSimulator
from mocapkit.suit.transport import SerialTransport, UdpTransport

__all__ = [
    "HostFusion",
    "Kind",
    "McapRecorder",
    "Packet",
    "ProtocolError",
    "Receiver",
    "ReceiverConfig",
    "ReceiverStats",
    "ReplayTransport",
    "SensorEvent",
    "SensorStats",
    "SerialTransport",
    "SuitSample",
    "SuitSimConfig",
    "SuitSimulator",
    "UdpTransport",
    "decode",
    "decode_recording",
    "replay",
]
