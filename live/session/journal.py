"""Everything a live session receives, on disk as it arrives, in a form a crash cannot spoil.

While QTM streams, each second of markers and of the force device's samples is appended to
``session.mcap.part`` (beside the final file) as ingest's block messages
(:mod:`data_schema.raw_mcap`): ``/live/markers`` (every 3D label QTM sends, metres, NaN when
lost) and ``/live/force`` (every channel of the force's analog board, or the nine values of
its force plate, in the units QTM states), each block its own chunk, flushed to the disk at
once. A process killed, or a connection lost, leaves every complete block readable
(:func:`read_journal` stops at the first record cut short, and says how many bytes it dropped).
When the session ends, the live runner reads the journal back and writes ``session.mcap`` from
its streams as ingest would have from the exports
(:func:`live.session.live_stage.raw_session`).

The journal's first record, ``live_journal``, says what it holds: the server, the labels, the
board or plate, the rates.
"""

from __future__ import annotations

import json
import os
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np

from core.errors import BadInput
from data_schema.raw_mcap import ENCODING, decode_block, encode_block

MARKERS, FORCE = "/live/markers", "/live/force"
FORMER = {"/live/analog": FORCE}    # the force's topic in journals of earlier versions
RECORD = "live_journal"


@dataclass
class Samples:
    """One stream's samples as they arrive: times (ns, the mocap's clock) and values (T, k)."""

    time_ns: list[np.ndarray] = field(default_factory=list)
    values: list[np.ndarray] = field(default_factory=list)
    samples: int = 0

    def add(self, time_ns: np.ndarray, values: np.ndarray) -> None:
        """Samples times (n,) and values (n, k) after those before."""
        self.time_ns.append(time_ns)
        self.values.append(values)
        self.samples += len(time_ns)

    def arrays(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """All samples so far: times (T,) and values (T, k)."""
        if not self.time_ns:
            return np.empty(0, np.int64), np.empty((0, k))
        return np.concatenate(self.time_ns), np.concatenate(self.values)


class Journal:
    """The append-only journal of one live session (``path``, an MCAP file)."""

    def __init__(self, path: Path, header: dict[str, Any]) -> None:
        from mcap.writer import CompressionType, Writer

        self.path, self.header = path, header
        self._file: IO[bytes] = open(path, "wb")  # noqa: SIM115 - closed by close()
        # a chunk per message: what is written is whole on the disk, a crash loses no block
        self._writer = Writer(self._file, chunk_size=1, compression=CompressionType.NONE)
        self._writer.start(profile="", library="phantom-pipeline live")
        self._writer.add_metadata(RECORD, {"header": json.dumps(header)})
        self._channels: dict[str, int] = {}
        self._sequence: dict[str, int] = {}
        for topic in (MARKERS, FORCE):
            schema = self._writer.register_schema(topic, ENCODING, b"")
            self._channels[topic] = self._writer.register_channel(topic, ENCODING, schema, {})
            self._sequence[topic] = 0
        self._sync()

    def append(self, topic: str, time_ns: np.ndarray, values: np.ndarray) -> None:
        """Write one block of a stream and flush it to the disk."""
        if len(time_ns) == 0:
            return
        t0 = max(0, int(time_ns[0]))
        self._writer.add_message(self._channels[topic], t0,
                                 encode_block(np.asarray(time_ns, np.int64),
                                              np.asarray(values, np.float64)),
                                 t0, sequence=self._sequence[topic])
        self._sequence[topic] += 1
        self._sync()

    def close(self) -> None:
        """Finish the MCAP (its summary) and close it."""
        self._writer.finish()
        self._file.close()

    def _sync(self) -> None:
        self._file.flush()
        os.fsync(self._file.fileno())


@dataclass
class JournalContent:
    """What a journal holds: its header, each stream's samples, and how its end was found."""

    header: dict[str, Any]
    streams: dict[str, tuple[np.ndarray, np.ndarray]]
    complete: bool               # closed by its session; False: cut short (a kill, a full disk)
    blocks: int                  # the blocks read
    cut_bytes: int               # bytes after the last whole record: a record cut short


def read_journal(path: Path) -> JournalContent:
    """Every complete block of a journal, in order; a record cut short ends the reading (what
    a file cut short raises while it is read: the end of the file inside a record)."""
    from mcap.exceptions import EndOfFile
    from mcap.records import Channel, Footer, Message, Metadata
    from mcap.stream_reader import StreamReader

    header: dict[str, Any] | None = None
    topics: dict[int, str] = {}
    blocks: dict[str, Samples] = {MARKERS: Samples(), FORCE: Samples()}
    complete, read, whole = False, 0, 0
    with open(path, "rb") as f:
        try:
            for record in StreamReader(f, skip_magic=False).records:
                whole = f.tell()              # the end of the record just read
                if isinstance(record, Metadata) and record.name == RECORD:
                    header = json.loads(record.metadata["header"])
                elif isinstance(record, Channel):
                    topics[record.id] = FORMER.get(record.topic, record.topic)
                elif isinstance(record, Message) and header is not None:
                    topic = topics[record.channel_id]
                    blocks[topic].add(*decode_block(record.data,
                                                    _values_per_sample(header, topic), path,
                                                    topic))
                    read += 1
                elif isinstance(record, Footer):
                    complete = True
        except (EndOfFile, struct.error):
            pass                    # a record cut short: everything before it is kept
        size = os.fstat(f.fileno()).st_size
    if header is None:
        raise BadInput(path, "not a live session's journal (no live_journal record)")
    return JournalContent(header, {t: s.arrays(_values_per_sample(header, t))
                                   for t, s in blocks.items()}, complete, read,
                          0 if complete else size - whole)


def _values_per_sample(header: dict[str, Any], topic: str) -> int:
    return 3 * len(header["labels"]) if topic == MARKERS else len(header["channels"])
