"""The MuJoCo scene: builds the model of an arena with all 24 object classes, and renders first-person views.

All bodies are mocap bodies placed from a ``WorldState``; the rules in ``mor.sim.rules`` decide motion, MuJoCo
draws it. Rendering settings follow docs/design.md (shadows and offscreen multisampling off). A frame is drawn with
the same MuJoCo calls as ``mujoco.Renderer`` (so the same pixels) without its per-frame costs: the GL context is
made current once and then only checked, and the camera and pixel buffer are reused (docs/performance.md).
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Sequence
from typing import Any

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


def _current_context_getter(gl: Any) -> Callable[[], Any] | None:
    """The function that returns this thread's current GL context on ``gl``'s backend (EGL or OSMesa), else None."""
    backend = sys.modules.get(type(gl).__module__)
    if hasattr(backend, "EGL"):
        return backend.EGL.eglGetCurrentContext
    if hasattr(backend, "osmesa"):
        return backend.osmesa.OSMesaGetCurrentContext
    return None


#: The size of the scene's geom buffer, as ``mujoco.Renderer`` allocates it.
_MAX_GEOM: int = 10_000


class Scene:
    """One MuJoCo model of an arena plus a lazily created first-person renderer.

    Create it inside the process that renders (one renderer per process); call ``close`` when done.
    """

    def __init__(self, arena: Arena, image_size: int, n_landmarks: int) -> None:
        self._setup(arena, mujoco.MjModel.from_xml_string(build_mjcf(arena, image_size, n_landmarks)), n_landmarks,
                    "fpv", (image_size, image_size), show_agent=False)

    def _setup(self, arena: Arena, model: mujoco.MjModel, n_landmarks: int, camera: str, size: tuple[int, int],
               show_agent: bool) -> None:
        """Bind the scene to ``model`` (built from ``build_mjcf``), drawn from its fixed camera ``camera`` into
        frames of ``size`` (width, height) pixels; ``show_agent``: draw the robot's own body (the first-person
        camera must not see it)."""
        self.arena = arena
        self.width, self.height = size
        self.model = model
        self.data = mujoco.MjData(self.model)
        self._scene_option = mujoco.MjvOption()
        self._scene_option.geomgroup[_AGENT_GROUP] = int(show_agent)
        self._wall_geoms = [self.model.geom(f"wall{k}").id for k in range(arena.n_walls)]
        self._wall_materials = [self.model.material(f"wall{i}").id for i in range(len(ALL_WALL_TEXTURES))]
        self._object_mocap = np.array([self.model.body(f"object{c}").mocapid[0] for c in range(N_CLASSES)])
        self._object_geoms = np.array([self.model.body_geomadr[self.model.body(f"object{c}").id] for c in range(N_CLASSES)])
        self._landmark_mocap = [self.model.body(f"landmark{i}").mocapid[0] for i in range(n_landmarks)]
        self._landmark_geoms = [self.model.geom(f"landmark{i}").id for i in range(n_landmarks)]
        self._agent_mocap = self.model.body("agent").mocapid[0]
        self._episode_mocap = self._episode_geoms = np.zeros(0, dtype=np.int64)
        # Views into MuJoCo's buffers, fetched once: each attribute access builds a new numpy wrapper.
        self._mocap_pos, self._mocap_quat = self.data.mocap_pos, self.data.mocap_quat
        self._geom_alpha = self.model.geom_rgba[:, 3]
        self._camera = mujoco.MjvCamera()
        self._camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self._camera.fixedcamid = self.model.camera(camera).id
        self._viewport = mujoco.MjrRect(0, 0, self.width, self.height)
        self._pixels = np.empty((self.height, self.width, 3), np.uint8)  # OpenGL's rows: bottom row first
        self._gl: Any = None  # mujoco.GLContext of the backend MUJOCO_GL names
        self._current_context: Callable[[], Any] | None = None
        self._gl_address: int | None = None
        self._mjv_scene: mujoco.MjvScene | None = None
        self._mjr_context: mujoco.MjrContext | None = None

    def set_episode(
        self, wall_textures: tuple[int, ...], object_classes: np.ndarray, landmarks: Sequence[tuple[np.ndarray, int]] = ()
    ) -> None:
        """Dress the scene for an episode: wall materials, which classes are present, landmark markers.

        landmarks: (target position (2,), class id) pairs; each marker takes its object's colour.
        Absent objects and unused markers get alpha 0, which MuJoCo skips entirely when building the scene.
        """
        for geom, texture in zip(self._wall_geoms, wall_textures, strict=True):
            self.model.geom_matid[geom] = self._wall_materials[texture]
        self._geom_alpha[self._object_geoms] = 0.0
        self._geom_alpha[self._landmark_geoms] = 0.0
        classes = np.asarray(object_classes, dtype=np.int64)
        self._episode_mocap = self._object_mocap[classes]
        self._episode_geoms = self._object_geoms[classes]
        for slot, (position, class_id) in enumerate(landmarks):
            self._mocap_pos[self._landmark_mocap[slot]] = (position[0], position[1], 0.0)
            self.model.geom_rgba[self._landmark_geoms[slot]] = (*object_class(int(class_id)).rgb, _LANDMARK_ALPHA)

    def set_state(self, state: WorldState) -> None:
        """Place the agent and the objects; the held object is hidden (it leaves the scene)."""
        x, y, theta = state.agent_pose
        self._mocap_pos[self._agent_mocap] = (x, y, 0.0)
        self._mocap_quat[self._agent_mocap] = _yaw_quaternion(theta)
        self._mocap_pos[self._episode_mocap, :2] = state.floor_positions
        self._geom_alpha[self._episode_geoms] = 1.0
        if state.held >= 0:
            self._geom_alpha[self._episode_geoms[state.held]] = 0.0
        mujoco.mj_kinematics(self.model, self.data)
        mujoco.mj_camlight(self.model, self.data)

    def render_first_person(self) -> np.ndarray:
        """The robot's camera image, (image_size, image_size, 3) uint8, a new array."""
        self.draw()
        return self.read_pixels()

    def draw(self) -> None:
        """Build MuJoCo's scene of the current state and hand its commands to OpenGL (llvmpipe draws on read)."""
        scene, context = self._ensure_renderer()
        self._make_current()
        mujoco.mjv_updateScene(self.model, self.data, self._scene_option, None, self._camera,
                               mujoco.mjtCatBit.mjCAT_ALL.value, scene)
        mujoco.mjr_render(self._viewport, scene, context)

    def read_pixels(self) -> np.ndarray:
        """The drawn frame, (height, width, 3) uint8, a new array (OpenGL's rows run bottom-up)."""
        mujoco.mjr_readPixels(self._pixels, None, self._viewport, self._mjr_context)
        return np.flipud(self._pixels).copy()

    def _make_current(self) -> None:
        """Make this scene's GL context current unless it already is: the check costs about a microsecond, while
        eglMakeCurrent costs tens (docs/performance.md). Backends without a check always switch."""
        if self._current_context is not None:
            current = self._current_context()
            if current and current.address == self._gl_address:
                return
        self._gl.make_current()

    def _ensure_renderer(self) -> tuple[mujoco.MjvScene, mujoco.MjrContext]:
        """The scene's geom buffer and MuJoCo's render context, created with the GL context on first use."""
        if self._mjr_context is None:
            try:
                self._gl = mujoco.GLContext(self.width, self.height)
                self._gl.make_current()
                self._mjr_context = mujoco.MjrContext(self.model, mujoco.mjtFontScale.mjFONTSCALE_150.value)
                mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN.value, self._mjr_context)
            except Exception as error:  # mujoco raises plain exceptions from the GL layer
                self.close()
                backend = os.environ.get("MUJOCO_GL", "")
                raise RenderBackendError(
                    f"could not create an OpenGL context with MUJOCO_GL={backend!r} ({error}); install Mesa's EGL "
                    "(apt-get install libegl1 libgl1-mesa-dri) or set MUJOCO_GL=osmesa with libosmesa6 installed"
                ) from None
            self._current_context = _current_context_getter(self._gl)
            self._gl_address = self._current_context().address if self._current_context is not None else None
            self._mjv_scene = mujoco.MjvScene(self.model, maxgeom=_MAX_GEOM)
        return self._mjv_scene, self._mjr_context

    def close(self) -> None:
        """Free the renderer's GL context."""
        if self._mjr_context is not None:
            with self._gl.as_current():
                self._mjr_context.free()
            self._mjr_context = None
        if self._gl is not None:
            self._gl.free()
            self._gl = None
        self._mjv_scene = None
