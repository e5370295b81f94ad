"""The numba stream decoder and batch encoders against the per-packet reference codec."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from mocapkit.suit.batch import (
    decode_stream,
    encode_orientation_many,
    encode_raw_many,
    pack_quat_many,
)
from mocapkit.suit.protocol import (
    Kind,
    decode,
    encode_bundle,
    encode_orientation,
    encode_raw,
    encode_status,
    pack_quat,
)


def _mixed_stream(rng: np.random.Generator) -> tuple[bytes, list[bytes]]:
    frames: list[bytes] = []
    for i in range(60):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        choice = i % 4
        if choice == 0:
            frames.append(encode_orientation(1 + i % 15, i, i * 1000, q))
        elif choice == 1:
            mag = None if i % 8 == 1 else rng.normal(0, 40, 3)
            frames.append(
                encode_raw(1 + i % 15, i, i * 1000, rng.normal(size=3), rng.normal(size=3), mag)
            )
        elif choice == 2:
            frames.append(encode_status(2, i, i, 3700, 25.0))
        else:
            frames.append(encode_bundle(i, i * 7, [(1, q), (5, -q), (15, q)]))
    garbage = [b"\x00\x01", b"\xa5\x11\x03", b"", bytes(rng.integers(0, 256, 9, dtype=np.uint8))]
    chunks = []
    for i, f in enumerate(frames):
        chunks.append(garbage[i % len(garbage)])
        chunks.append(f)
    return b"".join(chunks), frames


def test_decode_stream_equals_reference() -> None:
    rng = np.random.default_rng(3)
    data, frames = _mixed_stream(rng)
    dec = decode_stream(data)
    assert dec.n_frames == len(frames)
    rows = []
    for f in frames:
        p = decode(f)
        if p.kind is Kind.BUNDLE:
            rows += [(Kind.ORIENTATION, sid, p.seq, p.t_us, q, None) for sid, q in p.entries]
        else:
            rows.append((p.kind, p.sensor_id, p.seq, p.t_us, p.quat, p))
    assert len(dec) == len(rows)
    for i, (kind, sid, seq, t_us, q, p) in enumerate(rows):
        assert dec.sensor_id[i] == sid
        assert dec.seq[i] == seq
        assert dec.t_us[i] == t_us
        if q is not None:
            np.testing.assert_allclose(dec.quat[i], q, atol=1e-15)  # same arithmetic
        if kind is Kind.RAW:
            np.testing.assert_allclose(dec.gyr[i], p.gyr, atol=1e-15)
            np.testing.assert_allclose(dec.acc[i], p.acc, atol=1e-15)
            if p.mag is None:
                assert np.isnan(dec.mag[i]).all()
            else:
                np.testing.assert_allclose(dec.mag[i], p.mag, atol=1e-15)


@given(st.binary(max_size=500))
def test_decode_stream_survives_any_bytes(data: bytes) -> None:
    dec = decode_stream(data)
    assert dec.skipped_bytes <= len(data)


def test_batch_encoders_equal_reference() -> None:
    rng = np.random.default_rng(4)
    q = rng.normal(size=(50, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[0] = [1, 0, 0, 0]
    q[1] = [0, 0, 0, -1]
    packed = pack_quat_many(q)
    for i in range(len(q)):
        assert packed[i].tobytes() == pack_quat(q[i])
    t = np.arange(50) * 1000 + 2**32 - 10_000
    gyr, acc, mag = (
        rng.normal(0, 40, (50, 3)),
        rng.normal(0, 50, (50, 3)),
        rng.normal(0, 40, (50, 3)),
    )
    raw = encode_raw_many(3, 65530, t, gyr, acc, mag)
    raw6 = encode_raw_many(3, 0, t, gyr, acc, None)
    ori = encode_orientation_many(4, 7, t, q)
    for i in range(50):
        assert raw[i] == encode_raw(3, 65530 + i, int(t[i]), gyr[i], acc[i], mag[i])
        assert raw6[i] == encode_raw(3, i, int(t[i]), gyr[i], acc[i])
        assert ori[i] == encode_orientation(4, 7 + i, int(t[i]), q[i])
