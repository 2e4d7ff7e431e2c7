"""The sensor: gain, black level, noise, saturation and quantisation

SYNOPSIS

    >>> import numpy as np
    >>> from rotstar_mrcal.simulate.exposure import expose, full_scale_code
    >>> E = np.full((4, 4), 0.5)                       # irradiance, screen units
    >>> img = expose(E, gain=0.9, noise=0.0, bits=8)
    >>> img.dtype, int(img[0, 0])                      # round(0.45 * 255)
    (dtype('uint8'), 115)
    >>> expose(E, gain=4.0, noise=0.0, bits=16, value_bits=10)[0, 0] == full_scale_code(16)
    np.True_

The model, in fractions of full scale:

    signal = black + gain * irradiance
    value  = signal + N(0, noise^2 + shot * max(signal, 0))
    code   = round(clip(value, 0, 1) * (2^value_bits - 1))

noise is the additive (read) noise sigma; shot adds a signal-dependent,
Poisson-like variance (shot = 1 / full-well in electrons gives photon noise).
Noise is drawn before the clip, as in a real ADC. With bits = 16 and
value_bits = 10 or 12 (the D435 Y16 stream can carry 10-bit data) the codes
are scaled into the 16-bit range: stored = round(code * 65535 / (2^value_bits
- 1)), so full scale is 65535 and only 2^value_bits levels occur.
"""

from __future__ import annotations

import numpy as np


def full_scale_code(bits: int = 16) -> int:
    """The stored value of a saturated pixel (whatever value_bits is)"""
    return (1 << bits) - 1


def expose(
    irradiance: np.ndarray,
    *,
    gain: float = 0.9,
    black: float = 0.0,
    noise: float = 0.01,
    shot: float = 0.0,
    bits: int = 16,
    value_bits: int | None = None,
    rng: np.random.Generator | int | None = None,
) -> np.ndarray:
    """Irradiance -> uint8 (bits = 8) or uint16 (bits = 16) image; see the module docstring

    rng: a numpy Generator, or a seed for one (None: fresh entropy).
    """
    if bits not in (8, 16):
        raise ValueError(f"bits must be 8 or 16, not {bits}")
    vb = bits if value_bits is None else int(value_bits)
    if not 1 <= vb <= bits:
        raise ValueError(f"value_bits must be between 1 and {bits}, not {vb}")
    signal = np.multiply(irradiance, gain, dtype=np.float64)
    signal += black
    if noise > 0 or shot > 0:
        rng = np.random.default_rng(rng)
        n = rng.standard_normal(signal.shape, dtype=np.float32)
        if shot > 0:
            n *= np.sqrt(noise**2 + shot * np.maximum(signal, 0)).astype(np.float32)
        else:
            n *= np.float32(noise)
        signal += n
    top = (1 << vb) - 1
    np.clip(signal, 0.0, 1.0, out=signal)
    signal *= top
    np.rint(signal, out=signal)
    if vb != bits:
        signal *= ((1 << bits) - 1) / top
        np.rint(signal, out=signal)
    return signal.astype(np.uint8 if bits == 8 else np.uint16)
