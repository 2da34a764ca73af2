"""Benchmark: proportions of aged heads beside the published ones (issue 33, item 10).

Run ``python benchmarks/bench_age_proportions.py [--from AGE]`` from the
repository root.  Both built-in reference heads, taken as ``--from``-year-olds
(default 25), are aged to 3, 8, 12, 18, 40 and 70 years; for each age and sex
the script prints the measured proportions of the aged head
(:func:`workbench.services.age.proportions.measure_proportions`) beside the
published values (:func:`~workbench.services.age.proportions.published_proportions`)
and their ratio, and the same change relative to the source head (measured
ratio over the source's, published ratio at the age over the published ratio
at the source age: the reference heads are not average heads, so their own
proportions sit off the means, and the change is what the ageing controls).

Proportions (head frame: x to the subject's left, y up, z toward the face;
mm): eyeball diameter / face width zy-zy and / face height n-gn (published:
eyeball axial length, Gordon & Donzis 1985 and Fledelius & Christensen 1996,
over the mean zy-zy and n-gn of Weinberg et al. 2016); head-ear height
(vertex over porion) / face height n-me (published: Dezső 1967, same
children, 7-17 y); v-n / n-gn and neck / head circumference (no published
norm shipped: measured only).  Also the largest change of the angle between
neighbouring forehead triangles (degrees; a crease made by the warp) and the
seconds per age.  Nothing is asserted.
"""

from __future__ import annotations

import argparse
import sys
import time

from workbench.core.errors import InputError
from workbench.services.age.change import age_head
from workbench.services.age.proportions import published_proportions
from workbench.services.templates.cache import reference_head

AGES = (3.0, 8.0, 12.0, 18.0, 40.0, 70.0)
RATIOS = (
    ("eye_to_face_width", "eye / zy-zy"),
    ("eye_to_face_height", "eye / n-gn"),
    ("vault_to_face_height", "v-po / n-me"),
    ("v_n_to_n_gn", "v-n / n-gn"),
    ("neck_to_head_circumference", "neck / HC"),
)


def _published(sex: str, age: float, key: str) -> dict | None:
    value = published_proportions(sex, age).get(key)
    return value if isinstance(value, dict) else None


def _row(label: str, measured: float, source: float, pub: dict | None, pub_src: dict | None) -> str:
    text = f"  {label:12s} measured {measured:7.4f}"
    if pub is None:
        return text + "   published  -- (no norm here)"
    lo, hi = pub["band"]
    text += f"   published {pub['value']:7.4f} [{lo:.4f}-{hi:.4f}]   ratio {measured / pub['value']:6.3f}"
    if pub_src is not None:
        text += (
            f"   change vs source: measured {measured / source:6.3f}, "
            f"published {pub['value'] / pub_src['value']:6.3f}"
        )
    return text


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--from", dest="from_age", type=float, default=25.0)
    args = parser.parse_args(argv)
    a0 = args.from_age
    for sex in ("male", "female"):
        head = reference_head(sex)
        age_head(head, sex=sex, from_age=a0, to_age=a0)  # warm the tables' caches
        for age in AGES:
            pub_eye = published_proportions(sex, age)["eyeball_axial_mm"]
            src_eye = published_proportions(sex, a0)["eyeball_axial_mm"]
            t = time.perf_counter()
            try:
                r = age_head(head, sex=sex, from_age=a0, to_age=age)
            except InputError as exc:
                print(f"\n{sex} {a0:g} -> {age:g} y: not aged ({exc})")
                print(f"  published eyeball axial length {pub_eye:.2f} mm")
                for key, label in RATIOS:
                    pub = _published(sex, age, key)
                    if pub is not None:
                        print(f"  {label:12s} published {pub['value']:7.4f} ({pub['source']})")
                continue
            seconds = time.perf_counter() - t
            f = r.figures
            before, after = f["proportions"]["before"], f["proportions"]["after"]
            crease = f["forehead_crease_deg"]
            print(
                f"\n{sex} {a0:g} -> {age:g} y ({seconds:.2f} s): eyeball "
                f"{after['eyeball_mm']:.2f} mm (x{f['eyes']['scale']:.3f}; published axial "
                f"{pub_eye:.2f} mm, x{pub_eye / src_eye:.3f}); vault held by "
                f"{f['vault_height']}; forehead crease {crease['max_change_deg']:.2f} deg "
                f"(p99 {crease['p99_change_deg']:.2f}); lid gap min "
                f"{f['eyes']['lid_gap_mm']['after']['min']:.2f} mm (source "
                f"{f['eyes']['lid_gap_mm']['before']['min']:.2f})"
            )
            for key, label in RATIOS:
                print(
                    _row(
                        label,
                        after[key],
                        before[key],
                        _published(sex, age, key),
                        _published(sex, a0, key),
                    )
                )
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
