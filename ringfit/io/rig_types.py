"""The in-memory form of a rig file as its reader found it (docs/formats.md §17): named channels and metadata.

The readers (:mod:`ringfit.io.tdms`, :mod:`ringfit.io.matlab`,
:mod:`ringfit.io.csv_records`) build these; :mod:`ringfit.io.rig` turns them
into records. Kept apart so that the readers and the assembler never import
each other.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class RawChannel:
    """One channel of a rig file as read: ``data`` 1-D numbers, metadata where the file has it.

    ``name`` is the key a channel map uses; ``short`` the channel's own name
    (TDMS channel without its group); ``group`` the TDMS group (a record).
    """

    name: str
    data: np.ndarray
    short: str = ""
    group: str | None = None
    unit: str | None = None
    fs_hz: float | None = None
    axis: str | None = None
    angle_deg: float | None = None
    role: str | None = None


@dataclass
class RigFile:
    """What a rig reader found: channels plus file-level scalars (``fs_hz``, condition keys, …)."""

    source: str
    format: str
    channels: list[RawChannel] = field(default_factory=list)
    props: dict = field(default_factory=dict)
    #: ringfit's own key layout (docs/formats.md §4 / §9 keys), when the file holds it instead of channels.
    arrays: dict | None = None
    #: Dropped samples the reader found (a time column's jumps): ``[(i, missing)]``, ``missing`` samples lost
    #: after sample ``i`` of every channel; :mod:`ringfit.io.rig` fills them.
    gaps: list = field(default_factory=list)
    #: One-line notes of what the reader found and did (for the ``preprocessing`` list).
    notes: list = field(default_factory=list)

    def close(self) -> None:
        """Close the file behind lazy channels (nothing to do for channels read whole)."""
        for ch in self.channels:
            if isinstance(ch.data, LazyData):
                ch.data.close()


class LazyData:
    """A channel read on demand (a long TDMS recording): ``size``, ``dtype``, ``read(start, stop)``, ``close()``.

    The readers return one in :attr:`RawChannel.data` when asked for lazy
    channels; ``read`` gives the file's (scaled) values as float64.
    """

    size: int
    dtype: np.dtype
    ndim = 1

    def read(self, start: int, stop: int) -> np.ndarray:  # pragma: no cover - interface
        """Samples ``start:stop`` of the channel, float64."""
        raise NotImplementedError

    def close(self) -> None:
        """Release the file (nothing to do by default)."""


class ScaledChannel:
    """A :class:`LazyData` times a factor, in the form :class:`~ringfit.io.continuous.ContinuousRecord` reads
    channels (``length``, ``read(start, stop)``, ``close()``)."""

    def __init__(self, data: LazyData, factor: float):
        self.data, self.factor, self.length = data, float(factor), int(data.size)

    def read(self, start: int, stop: int) -> np.ndarray:
        """Samples ``start:stop`` (clipped to the channel's length) times the factor, float64."""
        stop = min(stop, self.length)
        if stop <= start:
            return np.zeros(0)
        return np.asarray(self.data.read(start, stop), dtype=np.float64) * self.factor

    def close(self) -> None:
        """Close the underlying channel."""
        self.data.close()

