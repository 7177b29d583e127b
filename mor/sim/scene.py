"""The MuJoCo scene: builds the model of an arena with all 24 object classes, and renders first-person views.

All bodies are mocap bodies placed from a ``WorldState``; the rules in ``mor.sim.rules`` decide motion, MuJoCo
draws it. Rendering settings follow DESIGN.md (shadows and offscreen multisampling off).
"""

from __future__ import annotations

import os
from collections.abc import Sequence

os.environ.setdefault("MUJOCO_GL", "egl")

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from mor.errors import RenderBackendError  # noqa: E402
from mor.sim.arena import Arena  # noqa: E402
from mor.sim.catalog import ALL_WALL_TEXTURES, N_CLASSES, OBJECT_HEIGHT, OBJECT_RADIUS, object_class  # noqa: E402
from mor.sim.rules import AGENT_RADIUS, CAMERA_FOV, WorldState  # noqa: E402

WALL_HEIGHT: float = 1.2
CAMERA_HEIGHT: float = 0.25
# Plane grid spacing (metres): one quad per plane; finer grids only cost software rendering time.
_PLANE_GRID: float = 100.0
_AGENT_GROUP: int = 3  # geom group of the robot's own body, hidden from its camera
_LANDMARK_RADIUS: float = 0.05
_LANDMARK_HEIGHT: float = 0.6
_LANDMARK_ALPHA: float = 0.8


def _rgb(values: tuple[float, float, float]) -> str:
    return " ".join(f"{v:.3f}" for v in values)


def _object_geom(class_id: int) -> str:
    cls = object_class(class_id)
    r, h = OBJECT_RADIUS, OBJECT_HEIGHT
    geom = {
        "cube": f'type="box" size="{0.7 * r:.3f} {0.7 * r:.3f} {h / 2:.3f}" pos="0 0 {h / 2:.3f}"',
        "sphere": f'type="sphere" size="{h / 2:.3f}" pos="0 0 {h / 2:.3f}"',
        "cylinder": f'type="cylinder" size="{0.8 * r:.3f} {h / 2:.3f}" pos="0 0 {h / 2:.3f}"',
        "capsule": f'type="capsule" size="{0.45 * h / 2:.3f} {0.55 * h / 2:.3f}" pos="0 0 {h / 2:.3f}"',
    }[cls.shape]
    return f'<geom {geom} rgba="{_rgb(cls.rgb)} 0" contype="0" conaffinity="0"/>'


def build_mjcf(arena: Arena, image_size: int, n_landmarks: int) -> str:
    """The MJCF text of ``arena`` with every object class, ``n_landmarks`` target markers and the robot."""
    textures = "\n".join(
        f'<texture name="wall{i}" type="2d" builtin="checker" rgb1="{_rgb(t.rgb1)}" rgb2="{_rgb(t.rgb2)}" '
        f'width="64" height="64"/>'
        f'<material name="wall{i}" texture="wall{i}" texrepeat="{1 / (2 * t.square_size):.4f} '
        f'{1 / (2 * t.square_size):.4f}" texuniform="true"/>'
        for i, t in enumerate(ALL_WALL_TEXTURES)
    )
    walls = []
    for k, (a, b) in enumerate(arena.walls()):
        direction = (b - a) / np.linalg.norm(b - a)
        middle = (a + b) / 2.0
        half_length = np.linalg.norm(b - a) / 2.0
        # Plane normal (local +z) must point into the arena: x-axis along -direction, y-axis up.
        walls.append(
            f'<geom name="wall{k}" type="plane" material="wall0" size="{half_length:.4f} {WALL_HEIGHT / 2} {_PLANE_GRID}" '
            f'pos="{middle[0]:.4f} {middle[1]:.4f} {WALL_HEIGHT / 2}" '
            f'xyaxes="{-direction[0]:.6f} {-direction[1]:.6f} 0 0 0 1" contype="0" conaffinity="0"/>'
        )
    objects = "\n".join(
        f'<body name="object{c}" mocap="true">{_object_geom(c)}</body>' for c in range(N_CLASSES)
    )
    landmarks = "\n".join(
        f'<body name="landmark{i}" mocap="true"><geom name="landmark{i}" type="cylinder" '
        f'size="{_LANDMARK_RADIUS} {_LANDMARK_HEIGHT / 2}" pos="0 0 {_LANDMARK_HEIGHT / 2}" rgba="1 1 1 0" '
        f'contype="0" conaffinity="0"/></body>'
        for i in range(n_landmarks)
    )
    extent = arena.half_extent + 1.0
    fovy = np.rad2deg(CAMERA_FOV)  # square images: vertical and horizontal fields of view are equal
    return f"""
<mujoco model="mor_{arena.shape}">
  <visual>
    <quality shadowsize="0" offsamples="0" numslices="12" numstacks="6" numquads="1"/>
    <global offwidth="{image_size}" offheight="{image_size}" fovy="{fovy}"/>
    <headlight ambient="0.45 0.45 0.45" diffuse="0.55 0.55 0.55" specular="0 0 0"/>
    <map znear="0.02" zfar="40"/>
    <rgba haze="0.55 0.65 0.80 1"/>
  </visual>
  <asset>
    {textures}
  </asset>
  <worldbody>
    <light directional="true" castshadow="false" pos="0 0 5" dir="0.2 0.3 -1" diffuse="0.3 0.3 0.3"
           specular="0 0 0"/>
    <geom name="floor" type="plane" size="{extent:.3f} {extent:.3f} {_PLANE_GRID}" rgba="0.62 0.60 0.57 1"
          contype="0" conaffinity="0"/>
    {"".join(walls)}
    {objects}
    {landmarks}
    <body name="agent" mocap="true" pos="0 0 0">
      <geom type="cylinder" size="{AGENT_RADIUS} 0.07" pos="0 0 0.07" rgba="0.15 0.15 0.15 1" group="{_AGENT_GROUP}"
            contype="0" conaffinity="0"/>
      <camera name="fpv" pos="0 0 {CAMERA_HEIGHT}" xyaxes="0 -1 0 0 0 1" fovy="{fovy}"/>
    </body>
  </worldbody>
</mujoco>
"""


def _yaw_quaternion(theta: float) -> np.ndarray:
    return np.array([np.cos(theta / 2.0), 0.0, 0.0, np.sin(theta / 2.0)])


class Scene:
    """One MuJoCo model of an arena plus a lazily created first-person renderer.

    Create it inside the process that renders (one renderer per process); call ``close`` when done.
    """

    def __init__(self, arena: Arena, image_size: int, n_landmarks: int) -> None:
        self.arena = arena
        self.image_size = image_size
        self.model = mujoco.MjModel.from_xml_string(build_mjcf(arena, image_size, n_landmarks))
        self.data = mujoco.MjData(self.model)
        self._renderer: mujoco.Renderer | None = None
        self._scene_option = mujoco.MjvOption()
        self._scene_option.geomgroup[_AGENT_GROUP] = 0
        self._wall_geoms = [self.model.geom(f"wall{k}").id for k in range(arena.n_walls)]
        self._wall_materials = [self.model.material(f"wall{i}").id for i in range(len(ALL_WALL_TEXTURES))]
        self._object_mocap = np.array([self.model.body(f"object{c}").mocapid[0] for c in range(N_CLASSES)])
        self._object_geoms = np.array([self.model.body_geomadr[self.model.body(f"object{c}").id] for c in range(N_CLASSES)])
        self._landmark_mocap = [self.model.body(f"landmark{i}").mocapid[0] for i in range(n_landmarks)]
        self._landmark_geoms = [self.model.geom(f"landmark{i}").id for i in range(n_landmarks)]
        self._agent_mocap = self.model.body("agent").mocapid[0]
        self._episode_mocap = self._episode_geoms = np.zeros(0, dtype=np.int64)

    def set_episode(
        self, wall_textures: tuple[int, ...], object_classes: np.ndarray, landmarks: Sequence[tuple[np.ndarray, int]] = ()
    ) -> None:
        """Dress the scene for an episode: wall materials, which classes are present, landmark markers.

        landmarks: (target position (2,), class id) pairs; each marker takes its object's colour.
        Absent objects and unused markers get alpha 0, which MuJoCo skips entirely when building the scene.
        """
        for geom, texture in zip(self._wall_geoms, wall_textures, strict=True):
            self.model.geom_matid[geom] = self._wall_materials[texture]
        self.model.geom_rgba[self._object_geoms, 3] = 0.0
        self.model.geom_rgba[self._landmark_geoms, 3] = 0.0
        classes = np.asarray(object_classes, dtype=np.int64)
        self._episode_mocap = self._object_mocap[classes]
        self._episode_geoms = self._object_geoms[classes]
        for slot, (position, class_id) in enumerate(landmarks):
            self.data.mocap_pos[self._landmark_mocap[slot]] = (position[0], position[1], 0.0)
            self.model.geom_rgba[self._landmark_geoms[slot]] = (*object_class(int(class_id)).rgb, _LANDMARK_ALPHA)

    def set_state(self, state: WorldState) -> None:
        """Place the agent and the objects; the held object is hidden (it leaves the scene)."""
        x, y, theta = state.agent_pose
        self.data.mocap_pos[self._agent_mocap] = (x, y, 0.0)
        self.data.mocap_quat[self._agent_mocap] = _yaw_quaternion(theta)
        self.data.mocap_pos[self._episode_mocap, :2] = state.floor_positions
        self.model.geom_rgba[self._episode_geoms, 3] = state.on_floor()
        mujoco.mj_kinematics(self.model, self.data)
        mujoco.mj_camlight(self.model, self.data)

    def render_first_person(self) -> np.ndarray:
        """The robot's camera image, (image_size, image_size, 3) uint8."""
        renderer = self._ensure_renderer()
        renderer.update_scene(self.data, camera="fpv", scene_option=self._scene_option)
        return renderer.render()

    def _ensure_renderer(self) -> mujoco.Renderer:
        if self._renderer is None:
            try:
                self._renderer = mujoco.Renderer(self.model, self.image_size, self.image_size)
            except Exception as error:  # mujoco raises plain exceptions from the GL layer
                backend = os.environ.get("MUJOCO_GL", "")
                raise RenderBackendError(
                    f"could not create an OpenGL context with MUJOCO_GL={backend!r} ({error}); install Mesa's EGL "
                    "(apt-get install libegl1 libgl1-mesa-dri) or set MUJOCO_GL=osmesa with libosmesa6 installed"
                ) from None
        return self._renderer

    def close(self) -> None:
        """Free the renderer's GL context."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
