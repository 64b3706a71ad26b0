"""The network's settings: its widths and its variant, with where it reads the press.

Plain data without torch: the command line reads the defaults, the choices and the bounds here.
``offsets`` is the one concept of where the network reads each point's offsets from the tip
(C = [tip start, tip end]); every module asks :class:`Offsets`, never the field's spelling.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass
from enum import StrEnum
from types import MappingProxyType
from typing import Any, ClassVar

from core.bounds import Bound, check_bounds, one_of
from core.errors import BadInput
from train.paper import K as PAPER_K

OFFSET_WIDTH = 32     # the heads' offset encoding e: numbers per point (ours, measured)


class Offsets(StrEnum):
    """Where the network reads each point's offsets from the tip (ours; the paper's network
    reads none: it learns them from absolute positions and C)."""

    NONE = "none"      # the paper's network
    GRAPH = "graph"    # the first graph layer reads [p, p - c_start, p - c_end]
    HEADS = "heads"    # the heads read an encoding e of them (docs/model.md)

    @property
    def press_independent(self) -> bool:
        """Whether the graph layers never read the press: a surface's features are then the
        same for every press, and a surface pressed again runs the heads alone."""
        return self is not Offsets.GRAPH

    @property
    def in_heads(self) -> bool:
        """Whether the heads read each point's offsets per press (and so the points)."""
        return self is Offsets.HEADS


@dataclass(frozen=True)
class CGNNConfig:
    """Widths of the network (the paper gives none; these are ours) and its variant:
    ``use_condition`` (False: noCond), ``offsets`` and the heads' encoding width
    ``offset_width`` (read only with ``offsets`` "heads")."""

    k: int = PAPER_K
    edge_widths: tuple[tuple[int, int], ...] = ((64, 64), (64, 64), (64, 64))
    disp_widths: tuple[int, ...] = (256, 128)
    force_widths: tuple[int, ...] = (128, 64, 32)
    use_condition: bool = True
    offsets: Offsets = Offsets.NONE
    offset_width: int = OFFSET_WIDTH

    BOUNDS: ClassVar[Mapping[str, Bound]] = MappingProxyType({
        "k": Bound(2, whole=True, why="neighbours per point, itself included"),
        "offset_width": Bound(1, whole=True),
    })

    def __post_init__(self) -> None:
        """The one check of the network (bad input, in one line): a known place for the
        offsets (given by its value, as a checkpoint keeps it: its member), only with C, and
        the bounds; the widths as tuples (lists, as a checkpoint keeps them, compare alike)."""
        object.__setattr__(self, "edge_widths", tuple(tuple(w) for w in self.edge_widths))
        object.__setattr__(self, "disp_widths", tuple(self.disp_widths))
        object.__setattr__(self, "force_widths", tuple(self.force_widths))
        object.__setattr__(self, "offsets", one_of(Offsets, self.offsets, "offsets"))
        if self.offsets is not Offsets.NONE and not self.use_condition:
            raise BadInput(None, f"offsets {self.offsets}: the tip's offsets are the condition "
                                 "C, which noCond removes")
        check_bounds(self, self.BOUNDS)

    def to_dict(self) -> dict[str, Any]:
        """Plain types, for a checkpoint loaded with ``weights_only``."""
        d = asdict(self)
        d["edge_widths"] = [list(w) for w in self.edge_widths]
        d["disp_widths"], d["force_widths"] = list(self.disp_widths), list(self.force_widths)
        d["offsets"] = self.offsets.value
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> CGNNConfig:
        """From :meth:`to_dict`'s form (an older form: :mod:`train.training.migrate` first)."""
        return cls(k=int(d["k"]), edge_widths=tuple(tuple(w) for w in d["edge_widths"]),
                   disp_widths=tuple(d["disp_widths"]), force_widths=tuple(d["force_widths"]),
                   use_condition=bool(d["use_condition"]), offsets=Offsets(d["offsets"]),
                   offset_width=int(d["offset_width"]))
