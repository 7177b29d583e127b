"""What can appear in the world: the 24 object classes and the wall-texture pools.

Class id ``c = shape_index * 6 + colour_index`` for 4 shapes x 6 colours (paper section 3.1).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeVar

SHAPES: tuple[str, ...] = ("cube", "sphere", "cylinder", "capsule")
COLOURS: dict[str, tuple[float, float, float]] = {
    "red": (0.85, 0.12, 0.10),
    "green": (0.10, 0.70, 0.20),
    "blue": (0.12, 0.30, 0.90),
    "yellow": (0.95, 0.85, 0.10),
    "magenta": (0.85, 0.15, 0.80),
    "cyan": (0.10, 0.80, 0.85),
}
COLOUR_NAMES: tuple[str, ...] = tuple(COLOURS)
N_CLASSES: int = len(SHAPES) * len(COLOURS)

#: Footprint radius (metres) of every object in the plane: used for overlap, obstruction and drops.
OBJECT_RADIUS: float = 0.15
#: Height (metres) of every object's top above the floor.
OBJECT_HEIGHT: float = 0.25


@dataclass(frozen=True)
class ObjectClass:
    """One of the 24 primitives."""

    class_id: int
    shape: str
    colour: str

    @property
    def rgb(self) -> tuple[float, float, float]:
        return COLOURS[self.colour]

    @property
    def name(self) -> str:
        return f"{self.colour}_{self.shape}"


ArrayLike = TypeVar("ArrayLike")  # a numpy array or a torch tensor


def object_class(class_id: int) -> ObjectClass:
    """The class with id ``class_id`` in [0, 24)."""
    if not 0 <= class_id < N_CLASSES:
        raise ValueError(f"class id {class_id} is outside [0, {N_CLASSES})")
    shape_index, colour_index = divmod(int(class_id), len(COLOURS))
    return ObjectClass(int(class_id), SHAPES[shape_index], COLOUR_NAMES[colour_index])


def shares_colour(classes: ArrayLike) -> ArrayLike:
    """(..., K) class ids (-1: an empty slot) -> (..., K) bool: another object of the same episode has this slot's
    colour (objects that differ by shape alone, which a far-away view confuses). numpy arrays or torch tensors."""
    present = classes >= 0
    colour = classes % len(COLOURS)
    same = (colour[..., :, None] == colour[..., None, :]) & present[..., :, None] & present[..., None, :]
    return same.sum(-1) > 1


@dataclass(frozen=True)
class WallTexture:
    """A checkerboard: two colours and the checker size (metres per square)."""

    name: str
    rgb1: tuple[float, float, float]
    rgb2: tuple[float, float, float]
    square_size: float


# Each wall side owns a colour family, so that the four (or more) sides of an arena can be told apart
# from their appearance alone (docs/design.md). Variants within a family differ in shade and checker size.
_FAMILIES: dict[str, tuple[tuple[float, float, float], ...]] = {
    "red": ((0.80, 0.20, 0.20), (0.65, 0.10, 0.25), (0.90, 0.40, 0.30)),
    "blue": ((0.20, 0.30, 0.80), (0.15, 0.45, 0.70), (0.35, 0.25, 0.75)),
    "green": ((0.20, 0.60, 0.25), (0.35, 0.55, 0.10), (0.15, 0.50, 0.40)),
    "orange": ((0.95, 0.60, 0.15), (0.85, 0.70, 0.20), (0.90, 0.50, 0.05)),
    "purple": ((0.55, 0.25, 0.65), (0.45, 0.15, 0.50), (0.65, 0.40, 0.75)),
    "grey": ((0.25, 0.25, 0.25), (0.45, 0.45, 0.45), (0.15, 0.20, 0.25)),
}
_LIGHT: dict[str, tuple[float, float, float]] = {
    "red": (0.98, 0.90, 0.88),
    "blue": (0.88, 0.92, 0.98),
    "green": (0.90, 0.98, 0.88),
    "orange": (0.20, 0.15, 0.10),
    "purple": (0.96, 0.92, 0.98),
    "grey": (0.95, 0.95, 0.95),
}
_SQUARE_SIZES: tuple[float, ...] = (0.25, 0.4)
#: The colour family of wall side k (k-th wall of the arena, counter-clockwise from the south wall).
WALL_FAMILIES: tuple[str, ...] = tuple(_FAMILIES)
MAX_WALLS: int = len(WALL_FAMILIES)


def _family_pool(family: str) -> tuple[WallTexture, ...]:
    return tuple(
        WallTexture(f"{family}{shade}_{int(size * 100)}cm", dark, _LIGHT[family], size)
        for shade, dark in enumerate(_FAMILIES[family])
        for size in _SQUARE_SIZES
    )


#: Per-side sub-pools: ``WALL_POOLS[k]`` is the pool wall k draws from.
WALL_POOLS: tuple[tuple[WallTexture, ...], ...] = tuple(_family_pool(f) for f in WALL_FAMILIES)
#: All textures in one list: the ``symmetric`` ablation draws every wall from it.
ALL_WALL_TEXTURES: tuple[WallTexture, ...] = tuple(t for pool in WALL_POOLS for t in pool)
TEXTURE_INDEX: dict[str, int] = {t.name: i for i, t in enumerate(ALL_WALL_TEXTURES)}
TEXTURE_POOLS: tuple[str, ...] = ("per_side", "symmetric")
