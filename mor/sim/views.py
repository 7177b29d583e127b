"""Pictures of the world: the schematic top-down view, side-by-side frames, PNG and MP4/GIF writers."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import imageio.v3 as iio
import numpy as np
from PIL import Image, ImageDraw

from mor.atomic import atomic_output
from mor.errors import ConfigError
from mor.sim.arena import Arena
from mor.sim.catalog import ALL_WALL_TEXTURES, OBJECT_RADIUS, object_class
from mor.sim.episode import EpisodeLayout
from mor.sim.geometry import heading_vector
from mor.sim.metrics import SUCCESS_RADIUS
from mor.sim.rules import AGENT_RADIUS, CAMERA_FOV, WorldState

TOP_DOWN_SIZE: int = 256
_BACKGROUND = (255, 255, 255)
_FLOOR = (214, 210, 203)


def _colour(rgb: tuple[float, float, float]) -> tuple[int, int, int]:
    return tuple(int(round(255 * c)) for c in rgb)  # type: ignore[return-value]


class TopDownCanvas:
    """Maps world metres to pixels of a square image with north up."""

    def __init__(self, arena: Arena, size: int = TOP_DOWN_SIZE) -> None:
        self.size = size
        self.scale = (size - 8) / (2.0 * arena.half_extent)
        self.image = Image.new("RGB", (size, size), _BACKGROUND)
        self.draw = ImageDraw.Draw(self.image)

    def px(self, point: np.ndarray) -> tuple[float, float]:
        """Pixel coordinates of a world point (2,)."""
        return (self.size / 2 + point[0] * self.scale, self.size / 2 - point[1] * self.scale)

    def circle(self, centre: np.ndarray, radius: float, **style: object) -> None:
        x, y = self.px(centre)
        r = radius * self.scale
        self.draw.ellipse((x - r, y - r, x + r, y + r), **style)


def draw_arena(canvas: TopDownCanvas, arena: Arena, wall_textures: tuple[int, ...]) -> None:
    """The floor polygon and each wall in its texture's dark colour."""
    canvas.draw.polygon([canvas.px(v) for v in arena.vertex_array], fill=_FLOOR)
    for (a, b), texture in zip(arena.walls(), wall_textures, strict=True):
        canvas.draw.line([canvas.px(a), canvas.px(b)], fill=_colour(ALL_WALL_TEXTURES[texture].rgb1), width=5)


def draw_object(canvas: TopDownCanvas, position: np.ndarray, class_id: int, hollow: bool = False) -> None:
    """An object (filled) or its target (hollow), square for cubes and round otherwise."""
    cls = object_class(class_id)
    colour = _colour(cls.rgb)
    style = {"outline": colour, "width": 2} if hollow else {"fill": colour, "outline": (40, 40, 40)}
    if cls.shape == "cube":
        x, y = canvas.px(position)
        r = 0.8 * OBJECT_RADIUS * canvas.scale
        canvas.draw.rectangle((x - r, y - r, x + r, y + r), **style)
    else:
        canvas.circle(position, OBJECT_RADIUS, **style)


def draw_agent(canvas: TopDownCanvas, pose: np.ndarray, holding: int | None) -> None:
    """The robot, its heading and its camera's field of view; a ring in the held object's colour."""
    x, y = canvas.px(pose[:2])
    view = 1.2 * canvas.scale
    start = -np.rad2deg(pose[2] + CAMERA_FOV / 2)
    canvas.draw.pieslice((x - view, y - view, x + view, y + view), start, start + np.rad2deg(CAMERA_FOV),
                         fill=(250, 240, 160))
    canvas.circle(pose[:2], AGENT_RADIUS, fill=(30, 30, 30))
    if holding is not None:
        canvas.circle(pose[:2], AGENT_RADIUS * 1.6, outline=_colour(object_class(holding).rgb), width=3)
    tip = pose[:2] + 0.35 * heading_vector(pose[2])
    canvas.draw.line([canvas.px(pose[:2]), canvas.px(tip)], fill=(0, 0, 0), width=2)


def draw_top_down(arena: Arena, layout: EpisodeLayout, state: WorldState, size: int = TOP_DOWN_SIZE) -> np.ndarray:
    """Top-down view, (size, size, 3) uint8: walls, targets (hollow, with their 1 m success circle), objects,
    and the agent with heading and field of view."""
    canvas = TopDownCanvas(arena, size)
    draw_arena(canvas, arena, layout.wall_textures)
    for target, class_id in zip(layout.target_positions, layout.object_classes, strict=True):
        canvas.circle(target, SUCCESS_RADIUS, outline=(170, 170, 170), width=1)
        draw_object(canvas, target, int(class_id), hollow=True)
    on_floor = state.on_floor()
    for index, class_id in enumerate(layout.object_classes):
        if on_floor[index]:
            draw_object(canvas, state.floor_positions[index], int(class_id))
    holding = int(layout.object_classes[state.held]) if state.held >= 0 else None
    draw_agent(canvas, state.agent_pose, holding)
    return np.asarray(canvas.image)


def side_by_side(first_person: np.ndarray, top_down: np.ndarray) -> np.ndarray:
    """The first-person image scaled (nearest) to the top-down view's height, placed to its left."""
    height = top_down.shape[0]
    scaled = np.asarray(Image.fromarray(first_person).resize((height, height), Image.NEAREST))
    gap = np.full((height, 4, 3), 255, np.uint8)
    return np.concatenate([scaled, gap, top_down], axis=1)


def write_png(path: Path, image: np.ndarray) -> Path:
    """Write ``image`` as PNG through a temporary name, so a partial file never has the final name."""
    with atomic_output(path) as partial:
        Image.fromarray(image).save(partial, format="PNG")
    return path


#: The video formats ``write_video`` writes, by file suffix.
VIDEO_SUFFIXES: tuple[str, ...] = (".mp4", ".gif")


def check_video_path(path: Path) -> Path:
    """``path`` if its suffix is one of ``VIDEO_SUFFIXES``; ConfigError otherwise (check before playing)."""
    if path.suffix.lower() not in VIDEO_SUFFIXES:
        raise ConfigError(f"{path}: a video must end in {' or '.join(VIDEO_SUFFIXES)}; change the file name")
    return path


def write_video(path: Path, frames: Iterable[np.ndarray], fps: int) -> Path:
    """Write frames as MP4 (H.264 through imageio-ffmpeg) or GIF, chosen by ``path``'s suffix."""
    suffix = check_video_path(path).suffix.lower()
    stack = np.stack(list(frames))
    with atomic_output(path) as partial:
        if suffix == ".gif":
            iio.imwrite(partial, stack, duration=1000 / fps, loop=0)
        else:
            iio.imwrite(partial, stack, fps=fps, codec="libx264", macro_block_size=1)
    return path
