"""Portraits of a head for a police appeal: front, three-quarter and profile, off-screen.

What a forensic artist hands over is a picture.  :func:`make_portrait` draws a
head as a studio photographer would take it, and :func:`write_portrait` /
:func:`save_portrait` write the pictures as PNG and TIFF at print resolution
(300 dpi), each carrying the words :data:`DISCLAIMER`, the head's template id
and the software version in its metadata.  The pictures are an **artistic
presentation** of a reconstruction: the colours (skin tone, lips, iris) are
defaults chosen by the user, not evidence (:mod:`workbench.core.appearance`);
the no-colour version (``colour=False``) draws every part in one neutral clay
and claims no colour at all.

Frame and units
---------------
The head is drawn in its Frankfort head frame (mm; x to the subject's left,
y up, z toward the face): a head given in another frame (a reconstruction
folder's ``head/`` pack is in the skull file's frame, perhaps a mirror image)
is first moved into the frame of its skull landmarks, so every portrait
shows the subject as they are, never mirrored.

Camera
------
A portrait lens: 85 mm on 35 mm film, whose 24 mm side spans a vertical view
angle of 2·atan(12/85) ≈ 16.1° (:data:`VIEW_ANGLE_DEG`), perspective.  The
pictures are square, ``size`` pixels a side.  The camera stands at the
subject's eye level (the eye centres' height) and at one distance for every
view, chosen so that the head, from its vertex to the menton, fills
:data:`HEAD_FILL` (80 %) of the frame height in the front view: about 1 m for
an adult head.  It turns about the vertical axis through the middle of the
head (x = 0, halfway along the head's depth), as if the subject turned on a
stool in front of a fixed camera and lights:

* ``front``: the camera on +z, looking at the face; the subject's right is on
  the viewer's left, as in a photograph;
* ``three_quarter``: turned 45° toward the subject's **right**: the right
  cheek is toward the camera and the face looks toward the viewer's right;
* ``profile``: the subject's **right** profile (camera on -x), the face toward
  the picture's right, as the report's side view.

Lights and shading
------------------
Physically based shading (VTK's PBR: metallic 0, the roughness of each
part's :class:`~workbench.core.appearance.Look`), lit by white directional
lights fixed relative to the camera (:data:`LIGHTS`): a key light 45° to the
viewer's right and 40° above (the side the face turns toward in the
three-quarter view and the profile, so the face is lit in all three), a fill
light from the viewer's left at about a third of the key's strength (soft,
even light with no black shadow side), a rim light from behind on the
viewer's left that parts the back of the head from the background, and a
weak bounce from below that opens the shadows under the chin and the nose,
as a reflector would.  The exposure puts a cheek turned to the key at about
the skin swatch's own sRGB value.

There are no cast shadows (:data:`SHADOW_NOTE` says why VTK's shadow-map and
SSAO passes are not used); soft shading in the creases (nostrils, the corners
of the eyes and mouth, under the lips and the jaw) is ambient occlusion,
ray-cast on the meshes and baked into the vertex colours
(:mod:`workbench.render.portrait_scene`, which also refines the skin so its
outline is round at print size and draws the eyes as finer painted globes),
so it is the same in every view and the pictures keep their multisample
anti-aliasing (:data:`MULTISAMPLES`).  The background is a neutral mid grey.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from os import PathLike
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from workbench.core.appearance import (
    DEFAULT_IRIS,
    DEFAULT_SKIN_TONE,
    IRIS_COLOURS,
    SKIN_TONES,
    SkinTexture,
)
from workbench.core.errors import InputError
from workbench.core.grooming import ARTISTIC_NOTE as GROOMING_NOTE
from workbench.core.grooming import GroomingError
from workbench.render.portrait_scene import (
    OCCLUSION_RAYS,
    OCCLUSION_REACH_MM,
    OCCLUSION_STRENGTH,
    DrawnPart,
    add_parts,
    portrait_parts,
)
from workbench.render.snapshots import _prefer_headless_gl

if TYPE_CHECKING:
    from workbench.model.appearance import Appearance
    from workbench.model.template import TemplateHead

#: the views, in the order they are drawn and written
VIEWS = ("front", "three_quarter", "profile")
#: each view's camera direction (from the head toward the camera) in the head frame
VIEW_DIRECTIONS = {
    "front": (0.0, 0.0, 1.0),
    "three_quarter": (-np.sqrt(0.5), 0.0, np.sqrt(0.5)),
    "profile": (-1.0, 0.0, 0.0),
}
#: the lens: focal length (mm) and the height of the 35 mm frame (its short side, mm)
LENS_MM, FILM_HEIGHT_MM = 85.0, 24.0
#: vertical view angle (degrees) of that lens: 2 atan(12 / 85) = 16.1°
VIEW_ANGLE_DEG = float(np.degrees(2.0 * np.arctan(FILM_HEIGHT_MM / 2.0 / LENS_MM)))
#: share of the frame height the head (vertex to menton) fills in the front view
HEAD_FILL = 0.8
#: picture size limits (pixels a side) and the print resolution written in the files
SIZE_LIMITS = (256, 8000)
DEFAULT_SIZE = 2000
DPI = 300
FORMATS = ("png", "tiff")
SUFFIX = {"png": ".png", "tiff": ".tif"}
#: a neutral mid grey (sRGB)
BACKGROUND_SRGB = (128, 128, 128)
#: anti-aliasing: multisamples of the render window
MULTISAMPLES = 4
SHADOW_NOTE = (
    "no cast shadows: VTK's shadow-map pass (enable_shadows) was tried off-screen here; with "
    "directional lights it drew hard bands across the cheeks and took 2-3x as long, with a "
    "spot key light blotches on the jaw. VTK's SSAO pass (enable_ssao) showed depth banding "
    "below a 1 mm bias and, on this EGL build, turns off the multisample anti-aliasing "
    "(jagged outlines; FXAA is not available). The creases are shaded by ambient occlusion "
    "ray-cast on the meshes (Embree) and baked into the vertex colours"
)
DISCLAIMER = (
    "artistic presentation of a reconstruction, not a photograph; "
    "colours are defaults, not evidence"
)


@dataclass(frozen=True)
class LightSpec:
    """A white light fixed relative to the camera (it turns with it).

    ``azimuth_deg`` turns it about the camera's up axis from the camera's
    direction (positive toward the viewer's right), ``elevation_deg`` raises
    it above the camera's horizontal plane; ``intensity`` is VTK's light
    intensity (PBR: radiance of a directional light).
    """

    name: str
    azimuth_deg: float
    elevation_deg: float
    intensity: float

    def direction(self, back: np.ndarray, right: np.ndarray, up: np.ndarray) -> np.ndarray:
        """Unit vector from the subject toward the light, given the camera's axes."""
        az, el = np.radians(self.azimuth_deg), np.radians(self.elevation_deg)
        d = np.cos(el) * (np.cos(az) * back + np.sin(az) * right) + np.sin(el) * up
        return d / np.linalg.norm(d)


#: the studio lights (see the module docstring)
LIGHTS = (
    LightSpec("key", 45.0, 40.0, 3.2),
    LightSpec("fill", -55.0, 10.0, 1.1),
    LightSpec("rim", -145.0, 30.0, 1.2),
    LightSpec("bounce", 0.0, -40.0, 0.5),
)


@dataclass(frozen=True)
class PortraitCamera:
    """One view's camera in the head frame (mm): position, focal point, view-up, angle."""

    view: str
    position: np.ndarray
    focal_point: np.ndarray
    up: np.ndarray
    view_angle_deg: float = VIEW_ANGLE_DEG

    @property
    def distance_mm(self) -> float:
        return float(np.linalg.norm(self.position - self.focal_point))

    def axes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(back, right, up)``: toward the camera, the picture's right and up (unit)."""
        back = self.position - self.focal_point
        back = back / np.linalg.norm(back)
        right = np.cross(self.up, back)
        right /= np.linalg.norm(right)
        return back, right, np.cross(back, right)

    def project(self, points: np.ndarray, size: int) -> np.ndarray:
        """``(k, 2)`` pixel positions (column, row from the top) of head-frame points."""
        back, right, up = self.axes()
        d = np.asarray(points, float).reshape(-1, 3) - self.position
        depth = -(d @ back)
        f = (size / 2.0) / np.tan(np.radians(self.view_angle_deg) / 2.0)
        col = size / 2.0 + f * (d @ right) / depth
        row = size / 2.0 - f * (d @ up) / depth
        return np.column_stack([col, row])

    def to_json(self) -> dict[str, Any]:
        return {
            "position_mm": [round(float(v), 2) for v in self.position],
            "focal_point_mm": [round(float(v), 2) for v in self.focal_point],
            "view_up": [round(float(v), 4) for v in self.up],
            "distance_mm": round(self.distance_mm, 1),
            "view_angle_deg": round(self.view_angle_deg, 2),
        }


@dataclass
class Portrait:
    """The pictures of one head: ``images`` ``{view: (size, size, 3) uint8 sRGB}``,
    row 0 at the top, and how they were made."""

    images: dict[str, np.ndarray]
    cameras: dict[str, PortraitCamera]
    size: int
    colour: bool
    skin_tone: str
    iris: str
    template_id: str
    skin_texture: bool = False
    seconds: dict[str, float] = field(default_factory=dict)
    head: TemplateHead | None = None
    #: the hair, brows, beard and moustache drawn, ``(kind, style)``; and the case's
    #: colours in words when a case's appearance was drawn
    grooming: tuple[tuple[str, str], ...] = ()
    appearance_note: str = ""

    def summary(self) -> dict[str, Any]:
        """What ``portrait.json`` records (plain data)."""
        import workbench

        return {
            "disclaimer": DISCLAIMER,
            "software": f"workbench {workbench.__version__}",
            "template_id": self.template_id,
            "frame": "head frame (x to the subject's left, y up, z toward the face), mm",
            "views": list(self.images),
            "size_px": [self.size, self.size],
            "dpi": DPI,
            "colour": self.colour,
            "skin": (
                "the fit's own skin texture"
                if self.colour and self.skin_texture
                else (self.skin_tone if self.colour else "clay (no colour claimed)")
            ),
            "iris": self.iris if self.colour else None,
            "case_appearance": self.appearance_note or None,
            "artistic_additions": (
                {"hair_and_brows": dict(self.grooming), "note": GROOMING_NOTE}
                if self.grooming
                else None
            ),
            "lens": {
                "focal_length_mm": LENS_MM,
                "film": "35 mm (24 mm frame height)",
                "vertical_view_angle_deg": round(VIEW_ANGLE_DEG, 2),
                "head_fill": HEAD_FILL,
                "projection": "perspective, camera at eye level",
            },
            "cameras": {v: c.to_json() for v, c in self.cameras.items()},
            "lights": [
                {
                    "name": s.name,
                    "azimuth_deg": s.azimuth_deg,
                    "elevation_deg": s.elevation_deg,
                    "intensity": s.intensity,
                    "relative_to": "the camera (azimuth + toward the viewer's right)",
                }
                for s in LIGHTS
            ],
            "shading": {
                "model": "physically based (VTK PBR), metallic 0, each part's roughness",
                "ambient_occlusion": (
                    f"ray-cast, {OCCLUSION_RAYS} rays a vertex within {OCCLUSION_REACH_MM:g} mm, "
                    f"up to {OCCLUSION_STRENGTH:.0%} of the light, baked into vertex colours"
                ),
                "multisamples": MULTISAMPLES,
                "shadows": SHADOW_NOTE,
                "background_srgb": list(BACKGROUND_SRGB),
            },
            "seconds": {k: round(v, 3) for k, v in self.seconds.items()},
        }


# ------------------------------------------------------------------ checks
def check_views(views: Iterable[str]) -> tuple[str, ...]:
    """The views asked for, in order, each once (``InputError`` for an unknown one)."""
    chosen = tuple(dict.fromkeys(str(v).strip() for v in views if str(v).strip()))
    unknown = [v for v in chosen if v not in VIEWS]
    if unknown or not chosen:
        raise InputError(
            ", ".join(unknown) or "views",
            "is not a portrait view" if unknown else "names no view",
            f"choose from {', '.join(VIEWS)}",
        )
    return chosen


def check_size(size: int) -> int:
    """The picture size in pixels (``InputError`` outside :data:`SIZE_LIMITS`)."""
    lo, hi = SIZE_LIMITS
    if isinstance(size, bool) or not isinstance(size, (int, np.integer)) or not lo <= size <= hi:
        raise InputError(
            f"size {size}", f"is not a picture size from {lo} to {hi} pixels", "e.g. 2000"
        )
    return int(size)


def check_formats(formats: Iterable[str]) -> tuple[str, ...]:
    chosen = tuple(dict.fromkeys(str(f).lower().lstrip(".") for f in formats))
    chosen = tuple("tiff" if f == "tif" else f for f in chosen)
    bad = [f for f in chosen if f not in FORMATS]
    if bad or not chosen:
        raise InputError(", ".join(bad) or "formats", "is not a picture format", "png or tiff")
    return chosen


def _check_looks(skin_tone: str, iris: str) -> None:
    if skin_tone not in SKIN_TONES:
        raise InputError(
            f"skin tone {skin_tone}", "is not a skin tone", f"choose one of {', '.join(SKIN_TONES)}"
        )
    if iris not in IRIS_COLOURS:
        raise InputError(
            f"iris {iris}", "is not an iris colour", f"choose one of {', '.join(IRIS_COLOURS)}"
        )


# ------------------------------------------------------------------ geometry
def portrait_head(head: TemplateHead) -> tuple[TemplateHead, bool]:
    """``head`` in the Frankfort frame of its skull landmarks (mm), and whether it moved
    there mirrored (its triangles then wound back, see
    :func:`workbench.services.age.change.in_frankfort_frame`)."""
    from workbench.services.age.change import in_frankfort_frame

    moved, changed = in_frankfort_frame(head)
    flipped = changed and not np.array_equal(moved.skin.faces, head.skin.faces)
    return moved, flipped


def _menton_height(head: TemplateHead) -> float:
    """The height (y, mm) of the chin's lowest point: skin menton, else gnathion, else the
    lowest point of the face region, else of the skin."""
    points = head.skin_landmarks.as_dict()
    for code in ("me", "gn"):
        if code in points and np.all(np.isfinite(points[code])):
            return float(points[code][1])
    face = head.regions.get("face") if head.regions else None
    v = head.skin.vertices if face is None else head.skin.vertices[np.asarray(face, np.int64)]
    return float(v[:, 1].min())


def portrait_cameras(head: TemplateHead, views: Sequence[str] = VIEWS) -> dict[str, PortraitCamera]:
    """One camera per view for a head in its head frame (see the module docstring).

    The distance is found in the front view: the head's points above the
    menton, projected, span :data:`HEAD_FILL` of the frame height.
    """
    skin = head.skin.vertices
    chin = _menton_height(head)
    top = float(skin[:, 1].max())
    above = skin[skin[:, 1] >= chin - 1.0]
    turn = np.array([0.0, 0.0, 0.5 * float(above[:, 2].min() + above[:, 2].max())])
    eye_y = float(np.mean(head.eye_centres[:, 1])) if len(head.eye_centres) else 0.5 * (top + chin)
    tan = np.tan(np.radians(VIEW_ANGLE_DEG) / 2.0)
    distance = (top - chin) / HEAD_FILL / 2.0 / tan
    centre_y = 0.5 * (top + chin)

    def camera(view: str, d: float, centre: float) -> PortraitCamera:
        direction = np.asarray(VIEW_DIRECTIONS[view], float)
        position = turn + direction * d
        position[1] = eye_y
        return PortraitCamera(
            view, position, turn + np.array([0.0, centre, 0.0]), np.array([0.0, 1.0, 0.0])
        )

    for _ in range(4):  # perspective: the face is nearer than the turning axis
        rows = camera("front", distance, centre_y).project(above, 1000)[:, 1]
        span = (rows.max() - rows.min()) / 1000.0
        middle = 0.5 * (rows.max() + rows.min()) / 1000.0 - 0.5  # + : the head sits low
        distance *= span / HEAD_FILL
        centre_y -= middle * 2.0 * tan * distance
    return {v: camera(v, distance, centre_y) for v in views}


# ------------------------------------------------------------------ drawing
def _place(plotter: Any, camera: PortraitCamera, lights: Sequence[Any]) -> None:
    """Point the plotter's camera and turn the lights with it."""
    cam = plotter.camera
    cam.position = tuple(camera.position)
    cam.focal_point = tuple(camera.focal_point)
    cam.up = tuple(camera.up)
    cam.view_angle = camera.view_angle_deg
    d = camera.distance_mm
    cam.clipping_range = (max(d - 500.0, 10.0), d + 500.0)
    back, right, up = camera.axes()
    for spec, light in zip(LIGHTS, lights, strict=True):
        light.SetFocalPoint(*camera.focal_point)
        light.SetPosition(*(camera.focal_point + spec.direction(back, right, up) * d))


def _plotter(size: int, parts: Sequence[DrawnPart]) -> tuple[Any, list[Any]]:
    """An off-screen plotter of ``size`` x ``size`` pixels with the parts and the lights."""
    _prefer_headless_gl()
    import pyvista as pv

    plotter = pv.Plotter(off_screen=True, window_size=[size, size], lighting="none")
    window = plotter.ren_win
    if window is not None:
        window.SetMultiSamples(MULTISAMPLES)
    plotter.set_background(np.asarray(BACKGROUND_SRGB, float) / 255.0)  # type: ignore[arg-type]
    add_parts(plotter, parts)
    lights = []
    for spec in LIGHTS:
        light = pv.Light(light_type="scene light", intensity=spec.intensity)
        light.positional = False
        plotter.add_light(light)
        lights.append(light)
    return plotter, lights


def _grab(window: Any) -> np.ndarray:
    """Render ``window`` once and read its picture: ``(h, w, 3)`` uint8, row 0 at the top."""
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkRenderingCore import vtkWindowToImageFilter

    window.Render()
    grab = vtkWindowToImageFilter()
    grab.SetInput(window)
    grab.SetInputBufferTypeToRGB()
    grab.ReadFrontBufferOff()
    grab.ShouldRerenderOff()
    grab.Update()
    image = grab.GetOutput()
    width, height, _ = image.GetDimensions()
    pixels = vtk_to_numpy(image.GetPointData().GetScalars()).reshape(height, width, -1)
    return np.ascontiguousarray(pixels[::-1, :, :3])


def make_portrait(
    head: TemplateHead,
    *,
    views: Sequence[str] = VIEWS,
    size: int = DEFAULT_SIZE,
    colour: bool = True,
    skin_tone: str = DEFAULT_SKIN_TONE,
    iris: str = DEFAULT_IRIS,
    skin_texture: SkinTexture | None = None,
    appearance: Appearance | None = None,
    progress: Callable[[str], None] | None = None,
) -> Portrait:
    """Draw ``head`` (any frame, mm; moved into its head frame first) in ``views``.

    ``size`` is the side of each square picture in pixels
    (:data:`SIZE_LIMITS`); ``colour`` False draws the clay version (and
    ignores ``skin_tone``, ``iris`` and ``skin_texture``).  ``skin_texture``
    (a fit's atlas, made for this skin) replaces the skin tone.
    ``appearance`` (a case's colours and hair, :class:`~workbench.model.appearance.Appearance`)
    replaces ``skin_tone`` and ``iris`` and adds its hair, brows and beard
    (in clay too).  Must run on the thread that may use VTK (the GUI thread
    in the window).
    """
    views = check_views(views)
    size = check_size(size)
    if appearance is not None:
        skin_tone, iris = appearance.tone, appearance.iris
    _check_looks(skin_tone, iris)
    seconds: dict[str, float] = {}
    t0 = time.perf_counter()
    framed, flipped = portrait_head(head)
    if skin_texture is not None and flipped:  # the triangles were wound back
        skin_texture = replace(skin_texture, corner_uv=skin_texture.corner_uv[:, ::-1])
    try:
        parts = portrait_parts(
            framed,
            colour=colour,
            skin_tone=skin_tone,
            iris=iris,
            skin_texture=skin_texture if colour else None,
            appearance=appearance,
        )
    except GroomingError:
        raise
    except ValueError as exc:  # a skin texture made for another skin
        raise InputError("skin texture", str(exc)) from None
    cameras = portrait_cameras(framed, views)
    seconds["prepare"] = time.perf_counter() - t0
    plotter, lights = _plotter(size, parts)
    images: dict[str, np.ndarray] = {}
    try:
        for view in views:
            t = time.perf_counter()
            _place(plotter, cameras[view], lights)
            images[view] = _grab(plotter.ren_win)
            seconds[view] = time.perf_counter() - t
            if progress is not None:
                progress(view)
    finally:
        plotter.close()
    seconds["render"] = time.perf_counter() - t0
    return Portrait(
        images,
        cameras,
        size,
        colour,
        skin_tone,
        iris,
        str(getattr(head, "template_id", "")),
        skin_texture is not None and colour,
        seconds,
        framed,
        appearance.grooming if appearance is not None else (),
        _appearance_note(appearance) if appearance is not None else "",
    )


def _appearance_note(appearance: Appearance) -> str:
    from workbench.services.appearance import colour_summary

    return colour_summary(appearance)


# ------------------------------------------------------------------ files
def _metadata(portrait: Portrait, view: str) -> dict[str, str]:
    """The text written into each picture (PNG text chunks; the TIFF's description)."""
    import workbench

    if not portrait.colour:
        look = "no colour (clay)"
    elif portrait.skin_texture:
        look = f"the fit's skin texture, {portrait.iris} iris"
    else:
        look = f"{portrait.skin_tone} skin, {portrait.iris} iris"
    if portrait.grooming:
        styles = ", ".join(f"{k} {v.replace('_', ' ')}" for k, v in portrait.grooming)
        look += f"; {styles} ({GROOMING_NOTE})"
    return {
        "Title": f"Portrait, {view.replace('_', ' ')} view",
        "Description": DISCLAIMER,
        "Source": f"template {portrait.template_id or 'unknown'}",
        "Comment": (
            f"{look}; {LENS_MM:g} mm lens on 35 mm film ({VIEW_ANGLE_DEG:.1f} deg vertical), "
            "camera at eye level; head frame, mm"
        ),
        "Software": f"workbench {workbench.__version__}",
    }


def write_image(
    image: np.ndarray, path: str | PathLike[str], fmt: str, metadata: Mapping[str, str]
) -> Path:
    """Write one picture atomically: PNG with ``metadata`` as text chunks, or TIFF (LZW)
    with it as the ImageDescription (Title. Description. Source. Comment.) and the
    Software tag; both at :data:`DPI` dots per inch."""
    from PIL import Image, PngImagePlugin

    from workbench.io.atomic import write_with_atomic

    picture = Image.fromarray(np.asarray(image, np.uint8), "RGB")

    def write(target: Path) -> None:
        if fmt == "png":
            info = PngImagePlugin.PngInfo()
            for key, value in metadata.items():
                info.add_itxt(key, value)
            picture.save(target, format="PNG", pnginfo=info, dpi=(DPI, DPI), compress_level=6)
        else:
            description = ". ".join(
                metadata[k] for k in ("Title", "Description", "Source", "Comment") if k in metadata
            )
            picture.save(
                target,
                format="TIFF",
                compression="tiff_lzw",
                dpi=(DPI, DPI),
                description=description,
                software=metadata.get("Software", ""),
            )

    return write_with_atomic(path, write)


def write_portrait(
    portrait: Portrait, out_dir: str | PathLike[str], formats: Sequence[str] = FORMATS
) -> dict[str, tuple[Path, ...]]:
    """Write ``portrait_<view>.png`` / ``.tif`` into ``out_dir`` (made if missing);
    ``{view: paths}``.  Existing files of those names are replaced (callers that
    must not replace anything use :func:`save_portrait`)."""
    formats = check_formats(formats)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written: dict[str, tuple[Path, ...]] = {}
    t0 = time.perf_counter()
    for view, image in portrait.images.items():
        meta = _metadata(portrait, view)
        written[view] = tuple(
            write_image(image, out / f"portrait_{view}{SUFFIX[f]}", f, meta) for f in formats
        )
    portrait.seconds["write"] = time.perf_counter() - t0
    return written


def render_portrait(
    head: TemplateHead,
    out_dir: str | PathLike[str] | None,
    *,
    views: Sequence[str] = VIEWS,
    size: int = DEFAULT_SIZE,
    colour: bool = True,
    skin_tone: str = DEFAULT_SKIN_TONE,
    iris: str = DEFAULT_IRIS,
    formats: Sequence[str] = FORMATS,
    skin_texture: SkinTexture | None = None,
) -> dict[str, np.ndarray] | dict[str, tuple[Path, ...]]:
    """The portraits of ``head``: ``{view: image}`` when ``out_dir`` is None, else the
    files written there (``{view: (png, tif)}``, see :func:`write_portrait`).

    See :func:`make_portrait` for the options; ``formats`` are ``"png"`` and
    ``"tiff"``.
    """
    if out_dir is not None:
        formats = check_formats(formats)
    portrait = make_portrait(
        head,
        views=views,
        size=size,
        colour=colour,
        skin_tone=skin_tone,
        iris=iris,
        skin_texture=skin_texture,
    )
    if out_dir is None:
        return portrait.images
    return write_portrait(portrait, out_dir, formats)


@dataclass(frozen=True)
class SavedPortrait:
    """What :func:`save_portrait` wrote: the folder, the pictures per view, the summary."""

    folder: Path
    files: dict[str, tuple[Path, ...]]
    summary: dict[str, Any]


def save_portrait(
    head: TemplateHead,
    out_dir: str | PathLike[str],
    *,
    force: bool = False,
    inputs: Iterable[str | PathLike[str] | None] = (),
    formats: Sequence[str] = FORMATS,
    notify: Callable[[str], None] | None = None,
    **options: Any,
) -> SavedPortrait:
    """Render and write a whole portrait folder: the pictures and ``portrait.json``.

    ``out_dir`` is written as a whole (:func:`workbench.io.outputs.staged_folder`):
    refused when it exists and is not empty unless ``force`` (the old one then
    kept as ``DIR.1``), and never when it holds one of ``inputs``.
    ``options`` go to :func:`make_portrait`.  ``workbench portrait`` and the
    window's Portrait dialog both write through here.
    """
    from workbench.io.atomic import write_json_atomic
    from workbench.io.outputs import relocate, staged_folder

    formats = check_formats(formats)
    final = Path(out_dir).absolute()
    with staged_folder(final, force, list(inputs), notify=notify) as temp:
        portrait = make_portrait(head, **options)
        files = write_portrait(portrait, temp, formats)
        summary = portrait.summary()
        summary["files"] = {v: [p.name for p in paths] for v, paths in files.items()}
        write_json_atomic(temp / "portrait.json", summary)
    return SavedPortrait(final, relocate(files, temp, final), summary)


__all__ = [
    "DISCLAIMER",
    "FORMATS",
    "HEAD_FILL",
    "LIGHTS",
    "SIZE_LIMITS",
    "VIEWS",
    "VIEW_ANGLE_DEG",
    "Portrait",
    "PortraitCamera",
    "SavedPortrait",
    "check_formats",
    "check_size",
    "check_views",
    "make_portrait",
    "portrait_cameras",
    "portrait_head",
    "render_portrait",
    "save_portrait",
    "write_image",
    "write_portrait",
]
