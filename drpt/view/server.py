"""The viewer: a local viser server showing a progressively path-traced scene.

:class:`Viewer` serves the scene's geometry as a raster preview (one
``add_mesh_simple`` per material, spheres as icospheres, an infinite plane
as a square ten times the size of the other geometry around it) and sends the path-traced frame of
:class:`~drpt.render.progressive.Progressive` as the background image
behind it. The browser's camera controls (orbit, dolly, truck) update the
camera: the path tracer starts over, at a quarter of the resolution while
the camera moves (the first frame after every move is always such a fast
one) and at the full preview size once it has been still for
:data:`SETTLE_SECONDS`. The raster shows while the camera moves and the
reduced frames refine, and hides when the full-size frame arrives.

One render thread traces every frame, the final render and accelerator
rebuilds; viser's callbacks only record what the user asked for, so the UI
never waits on the path tracer. The camera is a kernel input
(:class:`~drpt.render.camera.RayCamera`): moving it compiles nothing.

The preview frame is ``--size``'s height at the browser viewport's aspect
ratio (so it lines up with the raster); it refines up to ``--spp`` samples
per pixel. "render" writes ``--size`` at ``--spp`` to the output chosen on
the command line; "save camera" writes a ``PerspectiveCamera`` block (or
``OrthographicCamera``) to ``--camera-out``, or shows it when none was
given. The page accepts no paths and reads no files: the server holds the
one scene it was started with.
"""

from __future__ import annotations

import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import viser

from ..accel import KINDS
from ..errors import DrptError
from ..imageio import write_image
from ..options import INTEGRATORS, RenderOptions
from ..render.camera import camera_basis
from ..render.progressive import Progressive
from ..render.renderer import Renderer
from ..scene.model import Camera, Scene
from .pose import camera_block, camera_to_pose, look_at_point, pose_to_camera

SETTLE_SECONDS = 0.25  # the camera counts as still this long after its last move
MOVING_SCALE = 4  # the frame is this many times smaller in each direction while moving
JPEG_QUALITY = 90
CLOSE_SECONDS = 2.0  # with ``final``, the page counts as closed after this long without one


def display_image(image: np.ndarray, exposure: float, gamma: float) -> np.ndarray:
    """8-bit RGB of linear radiance, scaled by ``2**exposure`` and encoded as
    drpt writes .png files (clamp, ``1/gamma``)."""
    enc = np.clip(image * np.float32(2.0 ** exposure), 0.0, 1.0) ** (1.0 / gamma)
    return np.round(enc * 255.0).astype(np.uint8)


class Viewer:
    """A viewer of ``scene`` at http://host:port (``port=0``: a free one).
    ``final`` is ``True`` for ``render -gui``: "render" then ends
    :meth:`wait` (the caller renders), instead of rendering in the viewer.
    Frames go to the page as ``frame_format`` images (``"png"``: the exact
    8-bit :func:`display_image`)."""

    def __init__(self, scene: Scene, options: RenderOptions, *, host: str = "127.0.0.1",
                 port: int = 8080, output: Path | None = None, camera_out: Path | None = None,
                 gamma: float = 2.2, final: bool = False, verbose: bool = False,
                 frame_format: str = "jpeg"):
        self.scene_model = scene
        self.options = options
        self.output, self.camera_out, self.gamma, self.final = output, camera_out, gamma, final
        self.frame_format = frame_format  # "jpeg" (small, lossy) or "png" (exact 8-bit)
        self.frames_sent = 0
        self.error: BaseException | None = None
        self._lock = threading.Condition()
        self._camera: Camera = scene.camera
        self._aspect = options.width / options.height
        self._generation = 0
        self._last_move = 0.0
        self._render_request = False
        self._redisplay = False
        self._finished = False
        self._idle = False
        self._stop = False
        self.server = viser.ViserServer(host=host, port=port, verbose=verbose)
        self._build_page()
        self._thread = threading.Thread(target=self._run, name="drpt-view-render", daemon=True)
        self._thread.start()

    # ----------------------------------------------------------------- page
    @property
    def url(self) -> str:
        host = self.server.get_host()
        return f"http://{'127.0.0.1' if host in ('0.0.0.0', '') else host}:{self.server.get_port()}"

    def _build_page(self) -> None:
        s, gui, opt = self.server, self.server.gui, self.options
        cam = self.scene_model.camera
        position, _wxyz, fov = camera_to_pose(cam)
        lo, hi = self.scene_model.bounds()
        distance = float(np.linalg.norm((lo + hi) / 2 - position))
        if not (np.isfinite(distance) and distance > 0.0):
            distance = 1.0
        _f, _r, up = _basis(cam)
        s.scene.set_up_direction(tuple(float(c) for c in up))
        s.initial_camera.position = tuple(float(c) for c in position)
        s.initial_camera.look_at = tuple(float(c) for c in look_at_point(cam, distance))
        s.initial_camera.up = tuple(float(c) for c in up)
        s.initial_camera.fov = fov
        self._raster = self._add_geometry()

        self.status = gui.add_markdown("starting")
        self.integrator = gui.add_dropdown("integrator", INTEGRATORS, initial_value=opt.integrator)
        self.max_depth = gui.add_number("max depth (-1: unlimited)", initial_value=opt.path.max_depth,
                                        min=-1, step=1)
        self.exposure = gui.add_slider("exposure", min=-8.0, max=8.0, step=0.1, initial_value=0.0)
        self.accel = gui.add_dropdown("accelerator", KINDS, initial_value=opt.accel)
        self.render_button = gui.add_button("render" if not self.final else "render (close the viewer)")
        self.progress = gui.add_progress_bar(0.0, visible=False)
        self.save_button = gui.add_button("save camera")
        self.saved = gui.add_markdown("")

        for handle in (self.integrator, self.max_depth, self.accel):
            handle.on_update(lambda _e: self._changed())
        self.exposure.on_update(lambda _e: self._changed(restart=False))  # shown again, not traced
        self.render_button.on_click(lambda _e: self.request_render())
        self.save_button.on_click(lambda _e: self.save_camera())
        s.on_client_connect(self._connect)
        s.on_client_disconnect(self._disconnect)

    def _add_geometry(self) -> list:
        handles = []
        sc = self.scene_model
        mats = sc.materials
        tri = sc.triangles
        for m in np.unique(tri.material) if len(tri) else []:
            pos = tri.positions[tri.material == m].reshape(-1, 3).astype(np.float32)
            faces = np.arange(len(pos), dtype=np.uint32).reshape(-1, 3)
            handles.append(self.server.scene.add_mesh_simple(
                f"/scene/triangles_{int(m)}", pos, faces, color=_rgb(mats[int(m)].kd), side="double",
                cast_shadow=False, receive_shadow=False))
        for i in range(len(sc.spheres)):
            handles.append(self.server.scene.add_icosphere(
                f"/scene/sphere_{i}", radius=float(sc.spheres.radius[i]),
                color=_rgb(mats[int(sc.spheres.material[i])].kd),
                position=tuple(float(c) for c in sc.spheres.center[i]), cast_shadow=False,
                receive_shadow=False))
        planes = sc.planes
        if len(planes):
            lo, hi = sc.bounds()
            finite = bool(np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)))
            center = (lo + hi) / 2 if finite else np.zeros(3)
            half = 5.0 * max(float(np.linalg.norm(hi - lo)), 1e-6) if finite else 100.0
            for i in range(len(planes)):
                handles.append(self.server.scene.add_mesh_simple(
                    f"/scene/plane_{i}", *plane_quad(planes.normal[i], planes.offset[i], center, half),
                    color=_rgb(mats[int(planes.material[i])].kd), side="double", cast_shadow=False,
                    receive_shadow=False))
        return handles

    def _connect(self, client) -> None:
        client.camera.on_update(self._camera_moved)

    def _disconnect(self, _client) -> None:
        """With ``final``, closing the page continues: the render starts when
        no page has reconnected within :data:`CLOSE_SECONDS` (a reload does)."""
        if self.final:
            threading.Timer(CLOSE_SECONDS, self._closed_check).start()

    def _closed_check(self) -> None:
        if not self.server.get_clients():
            self.request_render()

    def _camera_moved(self, camera) -> None:
        cam = pose_to_camera(camera.position, camera.wxyz, camera.fov, like=self.scene_model.camera)
        with self._lock:
            self._camera = cam
            if camera.image_width > 0 and camera.image_height > 0:
                self._aspect = camera.image_width / camera.image_height
            self._generation += 1
            self._last_move = time.perf_counter()
            self._lock.notify_all()

    def _changed(self, restart: bool = True) -> None:
        with self._lock:
            if restart:
                self._generation += 1
            else:
                self._redisplay = True
            self._lock.notify_all()

    # ------------------------------------------------------------ actions
    @property
    def camera(self) -> Camera:
        """The camera the user left the view at."""
        with self._lock:
            return self._camera

    def settings(self) -> RenderOptions:
        """The options with the page's integrator, max depth and accelerator."""
        opt = replace(self.options, integrator=self.integrator.value,
                      path=replace(self.options.path, max_depth=int(self.max_depth.value)))
        if self.accel.value != self.options.accel:
            opt = replace(opt, accel=self.accel.value, bvh_method="auto", sah_threshold=None)
        return opt

    def request_render(self) -> None:
        """What the "render" button does: the final render (``final``: end
        :meth:`wait`)."""
        with self._lock:
            if self.final:
                self._finished = True
            else:
                self._render_request = True
            self._lock.notify_all()

    def save_camera(self) -> str:
        """What "save camera" does: the camera block, written to
        ``camera_out`` when given."""
        block = camera_block(self.camera)
        if self.camera_out is not None:
            self.camera_out.write_text(block)
            self.saved.content = f"camera written to `{self.camera_out}`"
        else:
            self.saved.content = "```\n" + block + "```"
        print(block, end="", flush=True)
        return block

    def wait(self) -> Camera:
        """Block until "render" (with ``final``) or :meth:`close`; the camera."""
        with self._lock:
            while not (self._finished or self._stop or self.error is not None):
                self._lock.wait(0.2)
        if self.error is not None:
            raise self.error
        return self.camera

    def _prog_done(self) -> bool:
        """Whether the render thread is waiting with a finished full-size frame."""
        return self._idle

    def close(self) -> None:
        with self._lock:
            self._stop = True
            self._lock.notify_all()
        self._thread.join(timeout=30)
        self.server.stop()

    # -------------------------------------------------------- render thread
    def _run(self) -> None:
        try:
            self._loop()
        except BaseException as e:  # reported by wait() in the main thread
            self.error = e
            self.status.content = f"error: {e}"
            with self._lock:
                self._lock.notify_all()

    def _loop(self) -> None:
        renderer: Renderer | None = None
        built_for = None
        prog: Progressive | None = None
        key = None
        shown_moving = None  # the camera generation of the last reduced frame published
        while True:
            with self._lock:
                if self._stop or self._finished:
                    return
                generation, camera, aspect = self._generation, self._camera, self._aspect
                # moving: the camera moved within SETTLE_SECONDS, or no reduced frame
                # of this camera is shown yet (the first frame after a move is the
                # fast one, however long the move took to arrive)
                moving = (time.perf_counter() - self._last_move < SETTLE_SECONDS
                          or generation != shown_moving)
                render_request, self._render_request = self._render_request, False
                redisplay, self._redisplay = self._redisplay, False
            try:
                opt = self.settings().validate()
            except DrptError as e:  # a control's value the renderer refuses: say so, wait for another
                self.status.content = f"**{e}**"
                with self._lock:
                    self._lock.wait(0.5)
                continue
            scene_key = (opt.accel, opt.bvh_method)
            if renderer is None or scene_key != built_for:
                self.status.content = f"building the {opt.accel} accelerator"
                renderer = Renderer(self.scene_model, replace(opt, progress=False))
                built_for, key = scene_key, None
            if render_request:
                try:
                    self._final_render(renderer, opt, camera)
                except (DrptError, OSError, ValueError) as e:
                    self.progress.visible = False
                    self.saved.content = f"**render failed: {e}**"
                continue
            H = max(1, self.options.height // (MOVING_SCALE if moving else 1))
            W = max(1, round(H * aspect))
            frame_opt = replace(opt, width=W, height=H, progress=False)
            new_key = (generation, W, H, opt.integrator, opt.path.max_depth)
            if new_key != key:
                if prog is None:
                    prog = Progressive(renderer, camera, frame_opt)
                else:
                    prog.base = renderer
                    prog.reset(camera, frame_opt)
                key = new_key
                if moving:
                    for h in self._raster:
                        h.visible = True
            self._idle = prog.done and not moving
            if prog.done:
                if redisplay:
                    self._publish(prog.frame(), moving)
                with self._lock:
                    self._lock.wait(SETTLE_SECONDS if moving else 0.5)
                continue
            self._publish(prog.step(), moving)
            if moving:
                shown_moving = generation

    def _publish(self, frame, moving: bool) -> None:
        rgb = display_image(frame.image, float(self.exposure.value), self.gamma)
        self.server.scene.set_background_image(rgb, format=self.frame_format, jpeg_quality=JPEG_QUALITY
                                               if self.frame_format == "jpeg" else None)
        if not moving:
            for h in self._raster:
                h.visible = False
        self.frames_sent += 1
        self.status.content = (f"**{frame.spp}** spp at {frame.width}x{frame.height} · "
                               f"{frame.samples_per_second / 1e6:.2f} Msamples/s · {frame.seconds:.1f} s")

    def _final_render(self, renderer, opt: RenderOptions, camera: Camera) -> None:
        if self.output is None:
            raise DrptError("no output image for the render")
        self.progress.visible = True
        self.progress.value = 0.0

        def on_pass(done: int, total: int) -> None:
            self.progress.value = 100.0 * done / total

        result = renderer.derive(replace(opt, progress=False), camera).render(on_pass)
        write_image(self.output, result.image, gamma=self.gamma)
        self.progress.visible = False
        self.saved.content = (f"`{self.output}`: {opt.width}x{opt.height}, {opt.spp} spp, "
                              f"{result.seconds:.1f} s")
        print(f"{self.output}: {opt.width}x{opt.height}, {opt.spp} spp, {result.seconds:.2f} s", flush=True)


def _basis(cam: Camera):
    return camera_basis(cam)


def plane_quad(normal, offset: float, center, half: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and faces of the square of half-size ``half`` on the plane
    ``dot(normal, x) = offset``, centred on ``center`` projected onto it."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    c = np.asarray(center, float) - n * (np.dot(n, center) - offset)
    a = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    v = np.array([c + half * (sa * a + sb * b) for sa, sb in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
    return v.astype(np.float32), np.array([[0, 1, 2], [0, 2, 3]], np.uint32)


def _rgb(c) -> tuple[int, int, int]:
    return tuple(int(round(255 * min(max(float(x), 0.0), 1.0))) for x in c)
