"""A numba parser of whitespace-separated decimal numbers, for large text tables (TRC):
~10x faster than ``np.fromstring`` on a million cells. Exact to the last bit for up to
15 significant digits (the mantissa is an exact integer and 10^k exact up to 10^22);
longer mantissas round once more (within 1 ulp). ``nan`` in any case is NaN; anything
else stops the parse (the caller then falls back to the strict parser and its message)."""

from __future__ import annotations

import numpy as np
from numba import njit

_POW10 = np.array([10.0**k for k in range(23)])


@njit(cache=True)
def parse_floats(buf: np.ndarray, out: np.ndarray) -> int:
    """Parse ``buf`` (uint8) into ``out``; returns the count, or -1 - (byte offset) of a
    token that is not a number or that does not fit in ``out``."""
    n = buf.shape[0]
    i = 0
    k = 0
    while i < n:
        c = buf[i]
        if c == 32 or c == 9 or c == 10 or c == 13:
            i += 1
            continue
        start = i
        if k >= out.shape[0]:  # more numbers than room: not the table the caller expects
            return -1 - start
        neg = False
        if c == 45 or c == 43:  # - +
            neg = c == 45
            i += 1
        if i + 2 < n + 1 and i < n and (buf[i] | 32) == 110:  # nan
            if i + 2 < n and (buf[i + 1] | 32) == 97 and (buf[i + 2] | 32) == 110:
                out[k] = np.nan
                k += 1
                i += 3
                if i < n and not (buf[i] == 32 or buf[i] == 9 or buf[i] == 10 or buf[i] == 13):
                    return -1 - start
                continue
            return -1 - start
        mant = 0
        digits = 0
        exp10 = 0
        seen = False
        while i < n and 48 <= buf[i] <= 57:
            if digits < 18:
                mant = mant * 10 + (buf[i] - 48)
                digits += 1
            else:
                exp10 += 1
            seen = True
            i += 1
        if i < n and buf[i] == 46:  # .
            i += 1
            while i < n and 48 <= buf[i] <= 57:
                if digits < 18:
                    mant = mant * 10 + (buf[i] - 48)
                    digits += 1
                    exp10 -= 1
                seen = True
                i += 1
        if not seen:
            return -1 - start
        if i < n and (buf[i] | 32) == 101:  # e
            i += 1
            eneg = False
            if i < n and (buf[i] == 45 or buf[i] == 43):
                eneg = buf[i] == 45
                i += 1
            e = 0
            edig = 0
            while i < n and 48 <= buf[i] <= 57:
                e = e * 10 + (buf[i] - 48)
                edig += 1
                i += 1
            if edig == 0:
                return -1 - start
            exp10 += -e if eneg else e
        if i < n and not (buf[i] == 32 or buf[i] == 9 or buf[i] == 10 or buf[i] == 13):
            return -1 - start
        v = float(mant)
        if exp10 > 0:
            v = v * _POW10[exp10] if exp10 < 23 else v * 10.0**exp10
        elif exp10 < 0:
            v = v / _POW10[-exp10] if -exp10 < 23 else v / 10.0 ** (-exp10)
        out[k] = -v if neg else v
        k += 1
    return k
