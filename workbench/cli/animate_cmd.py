"""``workbench animate HEAD``: pose a head with an expression, muscle contractions and the jaw.

HEAD is a template pack folder, a reconstruction folder (its ``head/`` pack)
or ``reference:male`` / ``reference:female``.  The skin is simulated to rest
in the pose (:class:`workbench.services.animation.animator.Animator`) and the last
frame's skin is written to ``--out`` (``.ply`` or ``.obj``; mm, in the
head's own frame, which a PLY header names).

``--out OUT.glb`` writes glTF 2.0 binary instead: the rest skin with every
palette expression (or those of ``--targets``) as a morph target settled from
rest, the eyes, teeth, tongue, mandible and cranium as nodes, in metres in
the frame of the head's PLY files (a reference head: the Frankfort head frame,
+Y up, +Z forward; a reconstruction: its skull file's frame).  With
``--expression`` that expression's weight is 1 by default and the file holds
a clip from neutral to it over ``--clip-seconds`` (1 s).  ``--arkit`` adds the
52 ARKit blendshape names as further targets, each a weighted sum of the
FACS action-unit targets (the built-in table
``data_tables/animation/arkit52_from_facs.csv``, an approximation, or
``--arkit FILE.csv``); the action units a recipe needs are settled too, and
shapes with an empty recipe are written as zero displacement.

A ``.glb`` carries the hair, brows, beard and moustache of ``--hair``,
``--brows``, ``--beard`` and ``--moustache`` (styles of
:mod:`workbench.core.grooming`; ``none`` removes a piece), or those a
reconstruction folder's ``case.fcase`` keeps with its colours (the window's
Appearance dock; ``--skin-tone`` and ``--iris`` change single choices), as
nodes of their own with the skin's morph targets (grown again on every
settled expression, so the brows rise with the brows and the beard opens
with the jaw), the skin painted under the hair.  They are artistic additions,
not evidence.

``--track FILE.json`` animates over time (keyframed expressions, muscles,
jaw, gaze and lids, and a timed phoneme track with Cohen-Massaro
coarticulation; the format is in :mod:`workbench.services.animation.track`).
The skin is simulated frame by frame (the first frame settled, then the
Animator's own 1/600 s steps, 20 a frame at 30 fps).  ``--out OUT.ply|.obj``
writes the last frame; ``--out DIR/frame_####.ply`` (or ``.obj``) writes
every frame, numbered from 0 with as many digits as there are ``#``, into
the folder DIR, which is written as a whole (an existing folder is refused
without ``--force`` and then kept as ``DIR.1``); ``--out OUT.glb`` writes
the track as a glTF clip: morph targets for the expressions the keys name
(and ``--targets``), for each key that is not a plain expression mix
(``key_<i>``) and for each spoken phoneme (``viseme_<P>``), with their
weights at every frame (LINEAR) as the clip.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from workbench.cli.common import add_force_option, add_style_options, chosen_appearance, output_path
from workbench.core.errors import InputError
from workbench.core.limits import MAX_CLIP_SECONDS, check_range
from workbench.model.template import TemplateHead
from workbench.pipelines.outcome import JobOutcome

if TYPE_CHECKING:
    from workbench.services.animation.animator import Animator
    from workbench.services.animation.track import Track

OUT_EXTENSIONS = (".ply", ".obj", ".glb")
ARKIT_BUILTIN = "builtin"  #: ``--arkit`` without a file
HEAD_FRAME = (
    "head frame: x to the subject's left (x = 0 midsagittal), y up, z toward the face, "
    "Frankfort Horizontal at y = 0; mm"
)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "animate",
        help="pose a head (expression, muscles, jaw) and write the skin",
        description="Simulate the skin of a head (mass-spring skin driven by the 24 muscles and "
        "the jaw) to rest in a pose and write the skin mesh (mm). Muscle contractions are 0 "
        "(relaxed) .. 1 (fully contracted); --muscle values override the expression's.",
    )
    p.add_argument(
        "head",
        help="template pack folder, reconstruction folder (with head/), or reference:male | "
        "reference:female",
    )
    p.add_argument(
        "--expression", default=None, metavar="NAME", help="palette expression (see --list)"
    )
    p.add_argument(
        "--muscle",
        action="append",
        default=[],
        metavar="NAME=C",
        help="contract one muscle, C in 0..1 (repeatable)",
    )
    p.add_argument("--jaw", type=float, default=None, metavar="DEG", help="jaw opening in degrees")
    p.add_argument(
        "--jaw-protrusion",
        type=float,
        default=0.0,
        metavar="MM",
        help="jaw forward shift in mm (default 0)",
    )
    p.add_argument("--list", action="store_true", help="print the expressions and muscles and exit")
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        help="output skin mesh (.ply or .obj), or .glb: glTF with every expression as a "
        "morph target; with --track also DIR/frame_####.ply (or .obj): every frame, numbered",
    )
    p.add_argument(
        "--track",
        type=Path,
        default=None,
        metavar="FILE.json",
        help='animate over time: {"fps": 30, "keys": [{"t": 0.5, "expression": "smile", '
        '"weight": 0.8}, {"t": 1.0, "muscles": {"mentalis": 0.4}, "jaw_deg": 8, "gaze": [10, 0], '
        '"lids": 0.5}], "phonemes": [{"p": "HH", "start": 1.2, "end": 1.3}]} (keys smoothstep-'
        "interpolated full poses; phonemes ARPAbet or TIMIT labels with times in s, "
        "coarticulated after Cohen & Massaro 1993). --out: .ply/.obj (last frame), "
        "DIR/frame_####.ply (every frame) or .glb (a clip)",
    )
    p.add_argument(
        "--targets",
        default=None,
        metavar="A,B,...",
        help=".glb only: the expressions to export as morph targets (default: all)",
    )
    p.add_argument(
        "--clip-seconds",
        type=float,
        default=1.0,
        metavar="S",
        help=".glb with --expression: length of the clip from neutral to it, above 0 and at "
        f"most {MAX_CLIP_SECONDS:g} s (default 1 s)",
    )
    p.add_argument(
        "--arkit",
        nargs="?",
        const=ARKIT_BUILTIN,
        default=None,
        metavar="FILE.csv",
        help=".glb only: add the 52 ARKit blendshape names as extra morph targets, each a "
        "weighted sum of FACS action-unit targets (the AUs a recipe needs are settled too). "
        "Alone: the built-in table (data_tables/animation/arkit52_from_facs.csv, an "
        "approximation: there is no official ARKit-FACS mapping); or a table of your own with "
        "the columns arkit_name,recipe,source,notes (recipe like au26:0.5;au27:0.5). Shapes "
        "with an empty recipe (gaze, tongueOut, cheekPuff ...) are written as zero displacement",
    )
    from workbench.core.appearance import DEFAULT_IRIS, DEFAULT_SKIN_TONE, IRIS_COLOURS, SKIN_TONES

    p.add_argument(
        "--skin-tone",
        choices=list(SKIN_TONES),
        default=None,
        help=".glb only: the skin's colour, a Monk Skin Tone swatch (mst1-mst10; light, medium "
        "and dark are mst3, mst6, mst9); an artistic default, not evidence. A fit-scan pack's "
        "own skin texture is used instead when HEAD is such a pack (default: the case's, else "
        f"{DEFAULT_SKIN_TONE})",
    )
    p.add_argument(
        "--iris",
        choices=list(IRIS_COLOURS),
        default=None,
        help=f".glb only: the iris colour painted on the eyes (default: the case's, else "
        f"{DEFAULT_IRIS})",
    )
    add_style_options(p, ".glb only, a node with the expressions as morph targets: ")
    p.add_argument(
        "--eyes",
        choices=["texture", "vertex"],
        default="texture",
        help=".glb only: the eyes' iris as a texture (default) or as vertex colours on finer "
        "eyeballs",
    )
    add_force_option(p)
    p.set_defaults(handler=run)


def _parse_muscles(items: list[str]) -> dict[str, float]:
    out: dict[str, float] = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            raise InputError(f"--muscle {item}", "expected NAME=C, e.g. zygomaticus_major_l=0.4")
        try:
            out[name.strip()] = float(value)
        except ValueError:
            raise InputError(f"--muscle {item}", f"'{value}' is not a number") from None
    return out


def load_head(spec: str) -> tuple[TemplateHead, str, list[Path]]:
    """``(head, frame description, input paths)`` for a HEAD argument."""
    if spec.startswith("reference:"):
        sex = spec.split(":", 1)[1]
        if sex not in ("male", "female"):
            raise InputError(
                spec, "unknown reference head", "use reference:male or reference:female"
            )
        from workbench.services.templates.cache import reference_head

        return reference_head(sex), HEAD_FRAME, []
    root = Path(spec)
    if not root.is_dir():
        raise InputError(
            root,
            "is not a folder",
            "give a template pack, a reconstruction folder, or reference:male | reference:female",
        )
    pack = root if (root / "template.json").is_file() else root / "head"
    if not (pack / "template.json").is_file():
        raise InputError(
            root,
            "is neither a template pack (template.json) nor a reconstruction folder (head/)",
        )
    from workbench.io.template_pack import load_template_pack

    head = load_template_pack(pack)
    try:
        frame = str(
            json.loads((pack / "template.json").read_text(encoding="utf-8")).get("frame", "")
        )
    except (OSError, ValueError):
        frame = ""
    return head, frame or HEAD_FRAME, [root]


def run(args: argparse.Namespace) -> JobOutcome | int:
    """The skin (or glTF, or frames) the options ask for; its key figures as values."""
    from workbench.services.animation.animator import EXPRESSIONS, Animator

    _check_clip_seconds(args.clip_seconds)
    if args.list:
        print("expressions: " + ", ".join(EXPRESSIONS))
    if args.track is not None:
        return _run_track(args)
    if args.out is not None and _frame_pattern(args.out) is not None:
        raise InputError(args.out, "a numbered frame sequence needs --track FILE.json")
    muscles = _parse_muscles(args.muscle)
    if args.expression is not None and args.expression not in EXPRESSIONS:
        raise InputError(
            f"--expression {args.expression}",
            "is not an expression",
            "valid names: " + ", ".join(EXPRESSIONS),
        )
    if args.out is None and not args.list:
        raise InputError("--out", "is required", "give the skin mesh to write (.ply or .obj)")
    if args.out is not None and args.out.suffix.lower() not in OUT_EXTENSIONS:
        raise InputError(
            args.out, "has an unsupported extension", "use .ply or .obj (or .glb for glTF)"
        )
    glb = args.out is not None and args.out.suffix.lower() == ".glb"
    if args.arkit is not None and not glb:
        raise InputError("--arkit", "needs --out FILE.glb", "ARKit targets are glTF morph targets")
    _check_glb_only(args, glb)
    targets = _glb_targets(args, muscles) if glb else None
    recipes = None
    if targets is not None and args.arkit is not None:
        from workbench.services.animation.gltf import arkit_needed, arkit_recipes

        recipes = arkit_recipes(None if args.arkit == ARKIT_BUILTIN else Path(args.arkit))
        targets = list(dict.fromkeys([*targets, *arkit_needed(recipes)]))
    head, frame, inputs = load_head(args.head)
    if args.list:
        print("muscles: " + ", ".join(m.code for m in head.muscles))
        if args.out is None:
            return 0
    from workbench.io.outputs import check_output_file

    check_output_file(args.out, inputs, args.force)  # before the simulation, not after
    if targets is not None:
        return _write_glb(args, head, targets, inputs, recipes, frame)
    anim = Animator(head)
    if args.expression is not None:
        anim.set_expression(args.expression)
    if muscles:
        anim.set_muscles(muscles)
    if args.jaw is not None or args.jaw_protrusion:
        anim.set_jaw(anim.jaw_deg if args.jaw is None else args.jaw, args.jaw_protrusion)
    steps = anim.settle()
    skin = anim.skin()
    moved = float(np.linalg.norm(skin.vertices - head.skin.vertices, axis=1).max())
    pose = f"expression={args.expression or 'none'} jaw={anim.jaw_deg:g}deg"
    if muscles:
        pose += " " + " ".join(f"{k}={v:g}" for k, v in muscles.items())
    with output_path(args.out, args, *inputs) as target:
        if target.suffix.lower() == ".ply":
            from workbench.io.mesh_formats import ply

            ply.write(
                target, skin, comments=[f"frame: {_ascii(frame)}", f"animate: {_ascii(pose)}"]
            )
        else:
            from workbench.io.meshes import write_mesh

            write_mesh(target, skin)
    print(
        f"wrote {args.out} ({skin.n_vertices} vertices; {pose}; settled in {steps} iterations; "
        f"largest skin movement {moved:.1f} mm)"
    )
    return JobOutcome(
        0,
        {
            "vertices": skin.n_vertices,
            "settle_iterations": int(steps),
            "largest_movement_mm": round(moved, 1),
            "output_bytes": args.out.stat().st_size,
        },
    )


def _check_clip_seconds(seconds: float) -> None:
    """``--clip-seconds``: above 0 and at most :data:`~workbench.core.limits.MAX_CLIP_SECONDS`."""
    check_range(
        seconds,
        "--clip-seconds",
        0.0,
        MAX_CLIP_SECONDS,
        unit="s",
        low_open=True,
        why="the clip from neutral to the expression; e.g. --clip-seconds 1",
    )


def _glb_targets(args: argparse.Namespace, muscles: dict[str, float]) -> list[str]:
    """The morph targets of a .glb (checked before the head is loaded)."""
    from workbench.services.animation.animator import EXPRESSIONS

    if muscles or args.jaw is not None or args.jaw_protrusion:
        raise InputError(
            args.out,
            "a .glb holds the palette expressions as morph targets, not --muscle/--jaw poses",
            "use --expression NAME (and --targets), or write .ply/.obj for a free pose",
        )
    if args.targets is None:
        names = list(EXPRESSIONS)
    else:
        names = [n.strip() for n in args.targets.split(",") if n.strip()]
        unknown = [n for n in names if n not in EXPRESSIONS]
        if unknown or not names:
            raise InputError(
                f"--targets {args.targets}",
                "names no expression"
                if not names
                else f"{', '.join(unknown)} is not an expression",
                "valid names: " + ", ".join(EXPRESSIONS),
            )
    if args.expression is not None and args.expression not in names:
        names.append(args.expression)
    return list(dict.fromkeys(names))


def _write_glb(
    args: argparse.Namespace,
    head: TemplateHead,
    names: list[str],
    inputs: list[Path],
    recipes: dict[str, dict[str, float]] | None = None,
    frame: str = "",
) -> JobOutcome:
    from workbench.services.animation.gltf import export_head_glb, ramp_keyframes

    weights = keyframes = None
    if args.expression is not None:
        weights = {args.expression: 1.0}
        keyframes = ramp_keyframes(args.expression, args.clip_seconds)
    looks = _looks(args, head)
    with output_path(args.out, args, *inputs) as target:
        _, settled, seconds = export_head_glb(
            head,
            target,
            names,
            keyframes,
            weights=weights,
            names_arkit=recipes,
            frame=frame,
            **looks,
        )
    size = args.out.stat().st_size
    clip = f"; clip neutral -> {args.expression} over {args.clip_seconds:g} s" if keyframes else ""
    if recipes:
        empty = sum(1 for mix in recipes.values() if not mix)
        clip += f"; {len(recipes)} ARKit targets, {empty} of them zero (no AU basis)"
    print(
        f"wrote {args.out} ({settled.rest['skin'].n_vertices} vertices, {len(names)} morph "
        f"targets settled in {seconds:.1f} s{clip}{_hair_note(looks)}; {size / 1e6:.1f} MB; "
        f"{_glb_frame(frame)})"
    )
    return JobOutcome(
        0,
        {
            "vertices": settled.rest["skin"].n_vertices,
            "morph_targets": len(names),
            "targets_seconds": round(seconds, 1),
            "output_bytes": size,
            "hair_and_brows": _hair_styles(looks),
        },
    )


def _ascii(text: str) -> str:
    return " ".join(text.encode("ascii", "replace").decode("ascii").split())


# ---------------------------------------------------------------------- --track
def _frame_pattern(out: Path) -> tuple[str, int, str] | None:
    """``(prefix, digits, suffix)`` of a file name like ``frame_####.ply`` (None: no ``#``)."""
    name = out.name
    if "#" not in name:
        return None
    start = name.index("#")
    digits = len(name) - start - len(name[start:].lstrip("#"))
    rest = name[start + digits :]
    if "#" in rest:
        raise InputError(out, "has more than one run of #", "use one, e.g. DIR/frame_####.ply")
    return name[:start], digits, rest


def _run_track(args: argparse.Namespace) -> JobOutcome:
    from workbench.services.animation.animator import Animator
    from workbench.services.animation.track import evaluate_track, load_track, play_track

    clash = [
        opt
        for opt, given in (
            ("--expression", args.expression is not None),
            ("--muscle", bool(args.muscle)),
            ("--jaw", args.jaw is not None),
            ("--jaw-protrusion", bool(args.jaw_protrusion)),
            ("--arkit", args.arkit is not None),
        )
        if given
    ]
    if clash:
        raise InputError(
            "--track",
            f"cannot be combined with {', '.join(clash)}",
            "put the poses into the track's keys",
        )
    if args.out is None:
        raise InputError(
            "--out", "is required", "give .ply/.obj (last frame), DIR/frame_####.ply or .glb"
        )
    suffix = args.out.suffix.lower()
    if suffix not in OUT_EXTENSIONS:
        raise InputError(
            args.out,
            "has an unsupported extension",
            "use .ply or .obj (last frame), DIR/frame_####.ply (every frame) or .glb (a clip)",
        )
    _check_glb_only(args, suffix == ".glb")
    pattern = _frame_pattern(args.out)
    if pattern is not None and suffix == ".glb":
        raise InputError(args.out, "a .glb holds the whole clip", "drop the #### from the name")
    if pattern is not None:
        _check_frame_folder(args.out.parent)
    track = load_track(args.track)
    head, frame, inputs = load_head(args.head)
    inputs = [*inputs, args.track]
    if suffix == ".glb":
        return _write_track_glb(args, head, track, inputs, frame)
    from workbench.io.outputs import check_output_file, check_output_folder

    if pattern is None:
        check_output_file(args.out, inputs, args.force)
    else:
        check_output_folder(args.out.parent, inputs, args.force)
    anim = Animator(head)
    frames = evaluate_track(track, anim.muscle_codes)
    t0 = time.perf_counter()
    label = f"track {args.track.name}"
    if pattern is None:
        for _ in play_track(anim, frames, track.fps):
            pass
        with output_path(args.out, args, *inputs) as target:
            _write_skin(target, anim, frame, f"{label} last frame t={frames.times[-1]:g}s")
        where = f"{args.out} (the last frame, t = {frames.times[-1]:g} s)"
    else:
        from workbench.io.outputs import staged_folder

        prefix, digits, rest = pattern
        with staged_folder(args.out.parent, args.force, inputs, notify=print) as folder:
            for i in play_track(anim, frames, track.fps):
                name = f"{prefix}{i:0{digits}d}{rest}"
                _write_skin(folder / name, anim, frame, f"{label} frame {i} t={frames.times[i]:g}s")
        where = f"{frames.n_frames} frames {args.out.parent / (prefix + '0' * digits + rest)} ..."
    seconds = time.perf_counter() - t0
    from workbench.services.animation.track import steps_per_frame

    print(
        f"wrote {where}; {frames.n_frames} frames at {track.fps:g} fps over "
        f"{frames.times[-1]:g} s, {len(track.keys)} keys, {len(track.phonemes)} phonemes; "
        f"{steps_per_frame(anim, track.fps)} simulation steps a frame, simulated in "
        f"{seconds:.1f} s ({anim.skin().n_vertices} vertices, mm)"
    )
    figures = {"vertices": anim.skin().n_vertices, "frames": frames.n_frames}
    if args.out.is_file():
        figures["output_bytes"] = args.out.stat().st_size
    return JobOutcome(0, figures)


def _check_frame_folder(folder: Path) -> None:
    """A frame sequence needs a folder of its own (it is written as a whole)."""
    here = Path.cwd().resolve()
    target = folder.resolve()
    if str(folder) in ("", ".") or target == here or target in here.parents:
        raise InputError(
            folder / "frame_####.ply",
            "a frame sequence is written into a folder of its own, replaced as a whole",
            "name a new folder, e.g. --out frames/frame_####.ply",
        )


def _write_skin(target: Path, anim: Animator, frame: str, what: str) -> None:
    skin = anim.skin()
    if target.suffix.lower() == ".ply":
        from workbench.io.mesh_formats import ply

        ply.write(target, skin, comments=[f"frame: {_ascii(frame)}", f"animate: {_ascii(what)}"])
    else:
        from workbench.io.meshes import write_mesh

        write_mesh(target, skin)


def _check_glb_only(args: argparse.Namespace, glb: bool) -> None:
    """``--hair`` and the other styles go into a .glb only."""
    from workbench.core.grooming import KINDS

    given = [f"--{k}" for k in KINDS if getattr(args, k, None) is not None]
    if given and not glb:
        raise InputError(
            ", ".join(given),
            "needs --out FILE.glb",
            "hair, brows, beard and moustache are exported as glTF nodes",
        )


def _looks(args: argparse.Namespace, head: TemplateHead) -> dict[str, Any]:
    """The colours of a .glb: the options, the case's appearance (a reconstruction
    folder's ``case.fcase``) with its hair, and a fit-scan pack's own skin texture."""
    from workbench.core.appearance import DEFAULT_IRIS, DEFAULT_SKIN_TONE
    from workbench.io.skin_colour_export import read_skin_texture

    appearance = chosen_appearance(args)
    looks: dict[str, Any] = {
        "skin_tone": args.skin_tone or DEFAULT_SKIN_TONE,
        "iris": args.iris or DEFAULT_IRIS,
        "eyes": args.eyes,
    }
    root = Path(str(args.head))
    for folder in (root, root / "head"):  # a fit-scan pack, or a folder holding one
        texture = read_skin_texture(folder, head.skin) if folder.is_dir() else None
        if texture is not None:
            looks["skin_texture"] = texture
            break
    if appearance is not None:
        looks.update(skin_tone=appearance.tone, iris=appearance.iris, appearance=appearance)
        if "skin_texture" not in looks:  # the case's colours, the skin painted under the hair
            from workbench.services.appearance import skin_look

            looks["looks"] = {"skin": skin_look(head, appearance)}
    return looks


def _hair_styles(looks: dict[str, Any]) -> str:
    appearance = looks.get("appearance")
    return ", ".join(f"{k} {v}" for k, v in appearance.grooming) if appearance else ""


def _hair_note(looks: dict[str, Any]) -> str:
    styles = _hair_styles(looks)
    return f"; {styles.replace('_', ' ')}: artistic additions, not evidence" if styles else ""


def _glb_frame(frame: str) -> str:
    """The frame line of a written ``.glb``: the head's own (that of its PLY files), metres."""
    return (
        f"metres, the frame of the head's PLY files ({(frame or HEAD_FRAME).removesuffix('; mm')})"
    )


def _write_track_glb(
    args: argparse.Namespace, head: TemplateHead, track: Track, inputs: list[Path], frame: str = ""
) -> JobOutcome:
    from workbench.io.outputs import check_output_file
    from workbench.services.animation.animator import EXPRESSIONS
    from workbench.services.animation.gltf import export_head_glb
    from workbench.services.animation.track import evaluate_track, glb_clip

    if args.targets is not None:
        names = [n.strip() for n in args.targets.split(",") if n.strip()]
        unknown = [n for n in names if n not in EXPRESSIONS]
        if unknown:
            raise InputError(
                f"--targets {args.targets}",
                f"{', '.join(unknown)} is not an expression",
                "valid names: " + ", ".join(EXPRESSIONS),
            )
    else:
        names = []
    used = [n for k in track.keys if k.is_mix for n in k.expressions if n != "neutral"]
    names = list(dict.fromkeys([*names, *used]))
    check_output_file(args.out, inputs, args.force)
    frames = evaluate_track(track)
    poses, keyframes = glb_clip(track, frames, names)
    if not names and not poses:
        raise InputError(args.track, "animates nothing a .glb can hold (only neutral keys)")
    looks = _looks(args, head)
    with output_path(args.out, args, *inputs) as target:
        _, settled, seconds = export_head_glb(
            head, target, names, keyframes, poses=poses, frame=frame, **looks
        )
    size = args.out.stat().st_size
    gaze = any(k.gaze != (0.0, 0.0) for k in track.keys)
    print(
        f"wrote {args.out} ({settled.rest['skin'].n_vertices} vertices, "
        f"{len(names) + len(poses)} morph targets ({len(names)} expressions, "
        f"{sum(1 for n in poses if n.startswith('key_'))} key poses, "
        f"{sum(1 for n in poses if n.startswith('viseme_'))} visemes) settled in {seconds:.1f} s; "
        f"clip of {frames.n_frames} frames at {track.fps:g} fps over {frames.times[-1]:g} s"
        + ("; gaze is not in the .glb" if gaze else "")
        + f"{_hair_note(looks)}; {size / 1e6:.1f} MB; {_glb_frame(frame)})"
    )
    return JobOutcome(
        0,
        {
            "vertices": settled.rest["skin"].n_vertices,
            "morph_targets": len(names) + len(poses),
            "output_bytes": size,
            "hair_and_brows": _hair_styles(looks),
        },
    )
