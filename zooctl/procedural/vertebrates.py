"""The vertebrate body plans: quadruped, biped, bird, fish, snake and the level biped dinosaur
(the arthropods are in `zooctl.procedural.arthropods`).

Each ``build_<plan>(params, palette)`` lays out joints and parts for the given proportions in the
model convention (Y up, -Z forward, feet on y = 0, the animal's right towards +X) and attaches the
plan's clips. ``palette`` is (main colour, secondary colour, belly colour), linear RGB; the shared
pieces (axes, eyes) are in `zooctl.procedural.plan_parts`.
"""

from __future__ import annotations

import numpy as np

from .body import Body, BodyParams, blob_part, limb_part
from .mesh import Part, polyline
from .motion import ClipBuilder, Limb, bob, gait, sway
from .plan_parts import SIDES, X, Y, Z, eyes, unit, v
from .skeleton import SkeletonBuilder

# -- quadruped --------------------------------------------------------------------------------
QUADRUPED = BodyParams(
    body_length=1.0, leg_length=0.55, neck_length=0.35, tail_length=0.5, head_size=0.2, girth=0.2
)


def build_quadruped(p: BodyParams, palette: tuple[np.ndarray, ...]) -> Body:
    main, second, belly = palette
    L, H, r, hs = p.body_length, p.leg_length, p.girth, p.head_size
    ys = H + 0.35 * r
    sk = SkeletonBuilder()
    sk.add("hips", v(0, ys, 0.42 * L))
    sk.add("spine1", v(0, ys + 0.05 * r, 0.14 * L), "hips")
    sk.add("spine2", v(0, ys + 0.05 * r, -0.14 * L), "spine1")
    sk.add("chest", v(0, ys, -0.42 * L), "spine2")
    neck_dir = unit((0, 0.75, -0.66))
    n0 = v(0, ys + 0.3 * r, -0.5 * L)
    sk.chain(
        ["neck1", "neck2", "head"],
        np.stack([n0 + neck_dir * p.neck_length * k for k in (0, 0.5, 1)]),
        "chest",
    )
    head = sk.position("head")
    tail_pts = [v(0, ys + 0.3 * r, 0.5 * L + 0.3 * r)]
    for k in range(1, 5):
        tail_pts.append(tail_pts[-1] + unit((0, 0.35 - 0.35 * k, 1.0)) * p.tail_length / 4)
    sk.chain(["tail1", "tail2", "tail3", "tail4"], np.stack(tail_pts[:4]), "hips")

    snout = unit((0, -0.3, -1))
    parts = [
        Part(
            "body",
            polyline(
                [
                    v(0, ys + 0.1 * r, 0.5 * L + 0.55 * r),
                    sk.position("hips"),
                    sk.position("spine1"),
                    sk.position("spine2"),
                    sk.position("chest"),
                    v(0, ys + 0.15 * r, -0.5 * L - 0.45 * r),
                ],
                36,
            ),
            _body_radii(36, r, 1.1 * r, 0.12),
            np.asarray(Y),
            ["hips", "spine1", "spine2", "chest"],
            None,
            main,
            belly,
            24,
        ),
        limb_part(
            "neck",
            [v(0, ys + 0.1 * r, -0.42 * L), n0, sk.position("neck2"), head],
            0.62 * r,
            0.45 * r,
            ["neck1", "neck2"],
            "chest",
            main,
            up=(0, 0.66, 0.75),
            n=18,
            segments=16,
        ),
        blob_part(
            "head",
            head - snout * 0.55 * hs,
            head + snout * 1.6 * hs,
            0.72 * hs,
            0.78 * hs,
            ["head"],
            "neck2",
            main,
            n=20,
            segments=18,
            taper=0.45,
            belly=belly,
        ),
        limb_part(
            "tail",
            [v(0, ys + 0.2 * r, 0.45 * L), *tail_pts],
            0.3 * r,
            0.05 * r,
            ["tail1", "tail2", "tail3", "tail4"],
            "hips",
            main,
            up=Y,
            n=22,
            segments=10,
        ),
        *eyes(head + snout * 0.45 * hs + v(0, 0.35 * hs, 0), 0.5 * hs, 0.12 * hs, "head"),
    ]
    for s, sx in SIDES:
        ear_base = head + v(sx * 0.35 * hs, 0.55 * hs, 0.15 * hs)
        parts.append(
            limb_part(
                f"ear_{s}",
                [ear_base, ear_base + v(sx * 0.15 * hs, 0.6 * hs, 0.1 * hs)],
                0.25 * hs,
                0.02 * hs,
                ["head"],
                None,
                second,
                up=(0, 0, -1),
                n=8,
                segments=10,
                flatten=0.35,
            )
        )
    limbs = []
    for front, z, anchor, phase_walk in ((True, -0.40 * L, "chest", 0.25), (False, 0.40 * L, "hips", 0.0)):
        for s, sx in SIDES:
            pre = ("front" if front else "back") + "_"
            x = sx * 0.55 * r
            top = v(x, ys - 0.15 * r, z)
            if front:
                knee, ankle, toe = (
                    v(x, 0.52 * H, z + 0.03 * H),
                    v(x, 0.1 * H, z),
                    v(x, 0.04 * H, z - 0.14 * H),
                )
            else:
                knee, ankle, toe = (
                    v(x, 0.55 * H, z - 0.1 * H),
                    v(x, 0.2 * H, z + 0.08 * H),
                    v(x, 0.04 * H, z - 0.06 * H),
                )
            joints = sk.chain(
                [pre + "upper_" + s, pre + "lower_" + s, pre + "foot_" + s],
                np.stack([top, knee, ankle]),
                anchor,
            )
            parts.append(
                limb_part(
                    pre + "leg_" + s,
                    [v(x, ys + 0.1 * r, z), top, knee, ankle, toe],
                    0.36 * r,
                    0.16 * r,
                    joints,
                    anchor,
                    second if not front else main,
                    n=24,
                    segments=12,
                )
            )
            phase = phase_walk + (0.5 if sx > 0 else 0.0)
            limbs.append((Limb(tuple(joints), phase % 1.0, X, None, (-1.0, 0.0, 0.0)), front))

    walk_limbs = [lb for lb, _ in limbs]
    # Trot: diagonal pairs in phase (left-front with right-back).
    trot_limbs = [
        Limb(
            lb.joints,
            0.0 if (lb.joints[0].endswith("_l") == front) else 0.5,
            lb.swing_axis,
            None,
            lb.bend_axis,
        )
        for lb, front in limbs
    ]

    def walk(b: ClipBuilder) -> None:
        gait(b, walk_limbs, swing=0.38, lift=0.0, bend=0.7)
        sway(b, ["spine1", "spine2"], Y, 0.03)
        sway(b, ["tail1", "tail2", "tail3", "tail4"], Y, 0.12, lag=0.1)
        b.rotate("neck1", X, 0.04 * b.wave(2))
        bob(b, "hips", 0.012 * H)

    def trot(b: ClipBuilder) -> None:
        gait(b, trot_limbs, swing=0.5, lift=0.0, bend=0.9)
        sway(b, ["tail1", "tail2", "tail3", "tail4"], X, 0.1, cycles=2, lag=0.1)
        b.rotate("neck1", X, 0.06 * b.wave(2, 0.25))
        bob(b, "hips", 0.025 * H)

    def idle(b: ClipBuilder) -> None:
        b.rotate("spine1", X, 0.015 * b.wave(2))
        b.rotate("neck1", Y, 0.35 * b.wave(1))
        b.rotate("neck2", X, 0.12 * b.wave(2, 0.25))
        sway(b, ["tail1", "tail2", "tail3", "tail4"], Y, 0.25, cycles=3, lag=0.1)

    return Body("quadruped", p, sk, parts, {"walk": (32, walk), "trot": (20, trot), "idle": (60, idle)})


def _body_radii(n: int, side: float, up: float, blunt: float) -> np.ndarray:
    """Radii (n, 2) of a torso: ellipsoid ends (rounded over ``blunt`` of the length), chest fuller."""
    x = np.linspace(0.0, 1.0, n)
    ends = np.minimum(x, 1.0 - x)
    prof = np.sqrt(np.clip(1.0 - (np.clip(blunt * 2 - ends, 0.0, None) / (blunt * 2)) ** 2, 0.0, 1.0))
    prof *= 0.92 + 0.12 * x
    return np.stack([side * prof, up * prof], 1)


# -- biped ------------------------------------------------------------------------------------
BIPED = BodyParams(
    body_length=0.55, leg_length=0.85, neck_length=0.1, tail_length=0.0, head_size=0.12, girth=0.15
)


def build_biped(p: BodyParams, palette: tuple[np.ndarray, ...]) -> Body:
    main, second, belly = palette
    L, H, r, hs = p.body_length, p.leg_length, p.girth, p.head_size
    y0 = H + 0.05
    sk = SkeletonBuilder()
    sk.add("pelvis", v(0, y0, 0))
    sk.add("spine", v(0, y0 + 0.35 * L, 0), "pelvis")
    sk.add("chest", v(0, y0 + 0.7 * L, 0), "spine")
    sk.add("neck", v(0, y0 + L, 0), "chest")
    sk.add("head", v(0, y0 + L + p.neck_length, 0), "neck")
    head = sk.position("head")
    parts = [
        Part(
            "torso",
            polyline([v(0, y0 - 0.12 * L, 0), v(0, y0 + L + 0.04, 0)], 30),
            _body_radii(30, 1.1 * r, 0.75 * r, 0.12)[::-1],
            np.array([0.0, 0.0, -1.0]),
            ["pelvis", "spine", "chest"],
            None,
            main,
            None,
            22,
        ),
        limb_part(
            "neck",
            [v(0, y0 + 0.85 * L, 0), head + v(0, 0.3 * hs, 0)],
            0.4 * r,
            0.35 * r,
            ["neck"],
            "chest",
            second,
            n=10,
            segments=14,
        ),
        blob_part(
            "head",
            head - v(0, 0.1 * hs, 0),
            head + v(0, 1.9 * hs, 0),
            0.8 * hs,
            0.85 * hs,
            ["head"],
            "neck",
            second,
            up=(0, 0, -1),
            n=18,
            segments=18,
        ),
        *eyes(head + v(0, 1.05 * hs, -0.72 * hs), 0.32 * hs, 0.12 * hs, "head"),
    ]
    limbs = []
    arm_len = 0.8 * H
    for s, sx in SIDES:
        sh = v(sx * 1.2 * r, y0 + 0.88 * L, 0)
        d = unit((sx * 0.3, -1.0, 0.0))
        pts = [sh, sh + d * 0.45 * arm_len, sh + d * 0.85 * arm_len]
        joints = sk.chain([f"upperarm_{s}", f"forearm_{s}", f"hand_{s}"], np.stack(pts), "chest")
        parts.append(
            limb_part(
                f"arm_{s}",
                [sh - v(sx * 0.3 * r, 0, 0), *pts, sh + d * arm_len],
                0.36 * r,
                0.2 * r,
                joints,
                "chest",
                second,
                n=22,
                segments=12,
            )
        )
        limbs.append(Limb(tuple(joints), 0.5 if sx < 0 else 0.0, X, None, X))
        hip = v(sx * 0.5 * r, H, 0)
        knee, ankle, toe = (
            v(sx * 0.5 * r, 0.5 * H, -0.02 * H),
            v(sx * 0.5 * r, 0.07 * H, 0.02 * H),
            v(sx * 0.5 * r, 0.04 * H, -0.17 * H),
        )
        joints = sk.chain([f"thigh_{s}", f"shin_{s}", f"foot_{s}"], np.stack([hip, knee, ankle]), "pelvis")
        parts.append(
            limb_part(
                f"leg_{s}",
                [hip + v(0, 0.1 * L, 0), hip, knee, ankle, toe],
                0.5 * r,
                0.22 * r,
                joints,
                "pelvis",
                main,
                n=26,
                segments=12,
            )
        )
        limbs.append(Limb(tuple(joints), 0.0 if sx < 0 else 0.5, X, None, (-1.0, 0.0, 0.0)))
    tail = []
    if p.tail_length > 0.02:
        t0 = v(0, y0 - 0.05 * L, 0.5 * r)
        pts = np.stack([t0 + unit((0, -0.6 + 0.3 * k, 1)) * p.tail_length * k / 3 for k in range(3)])
        tail = sk.chain(["tail1", "tail2", "tail3"], pts, "pelvis")
        parts.append(
            limb_part(
                "tail",
                [t0 - v(0, 0, 0.5 * r), *pts, pts[-1] + unit((0, 0.3, 1)) * p.tail_length / 3],
                0.3 * r,
                0.05 * r,
                tail,
                "pelvis",
                main,
                up=Y,
                n=20,
                segments=10,
            )
        )
    legs = [lb for lb in limbs if lb.joints[0].startswith("thigh")]
    arms = [lb for lb in limbs if lb.joints[0].startswith("upperarm")]

    def walk(b: ClipBuilder) -> None:
        gait(b, legs, swing=0.45, lift=0.0, bend=0.8)
        gait(b, arms, swing=0.3, lift=0.0, bend=0.25)
        b.rotate("chest", Y, 0.08 * b.wave(1))
        b.rotate("pelvis", Y, -0.06 * b.wave(1))
        bob(b, "pelvis", 0.015 * H, offset=0.25)
        if tail:
            sway(b, tail, Y, 0.15)

    def idle(b: ClipBuilder) -> None:
        b.rotate("chest", X, 0.02 * b.wave(2))
        b.rotate("neck", Y, 0.4 * b.wave(1))
        b.rotate("head", X, 0.08 * b.wave(2, 0.25))
        for s, sx in SIDES:
            b.rotate(f"upperarm_{s}", Z, sx * 0.06 * b.wave(2))
        if tail:
            sway(b, tail, Y, 0.25, cycles=2)

    return Body("biped", p, sk, parts, {"walk": (36, walk), "idle": (60, idle)})


# -- bird -------------------------------------------------------------------------------------
BIRD = BodyParams(
    body_length=0.35,
    leg_length=0.16,
    neck_length=0.1,
    tail_length=0.16,
    head_size=0.07,
    girth=0.1,
    wing_length=0.45,
)


def build_bird(p: BodyParams, palette: tuple[np.ndarray, ...]) -> Body:
    main, second, belly = palette
    L, H, r, hs, W = p.body_length, p.leg_length, p.girth, p.head_size, p.wing_length
    beak = np.array([0.85, 0.55, 0.1])
    yb = H + r
    sk = SkeletonBuilder()
    sk.add("hips", v(0, yb, 0.15 * L))
    sk.add("chest", v(0, yb + 0.15 * r, -0.25 * L), "hips")
    nd = unit((0, 0.85, -0.5))
    n0 = v(0, yb + 0.5 * r, -0.4 * L)
    sk.chain(
        ["neck1", "neck2", "head"], np.stack([n0 + nd * p.neck_length * k for k in (0, 0.5, 1)]), "chest"
    )
    head = sk.position("head")
    tail0 = v(0, yb + 0.1 * r, 0.45 * L)
    sk.add("tail", tail0, "hips")
    fwd = unit((0, -0.1, -1))
    parts = [
        blob_part(
            "body",
            v(0, yb - 0.05 * r, 0.55 * L),
            v(0, yb + 0.3 * r, -0.55 * L),
            r,
            0.95 * r,
            ["hips", "chest"],
            None,
            main,
            n=28,
            segments=22,
            belly=belly,
        ),
        limb_part(
            "neck",
            [v(0, yb + 0.2 * r, -0.35 * L), n0, sk.position("neck2"), head],
            0.55 * r,
            0.45 * r,
            ["neck1", "neck2"],
            "chest",
            main,
            up=(0, 0.5, 0.85),
            n=14,
            segments=14,
        ),
        blob_part(
            "head",
            head - fwd * 0.7 * hs,
            head + fwd * 0.9 * hs,
            0.8 * hs,
            0.85 * hs,
            ["head"],
            "neck2",
            main,
            n=16,
            segments=16,
        ),
        limb_part(
            "beak",
            [head + fwd * 0.6 * hs, head + fwd * 2.3 * hs],
            0.38 * hs,
            0.02 * hs,
            ["head"],
            None,
            beak,
            up=Y,
            n=10,
            segments=10,
            flatten=0.7,
        ),
        *eyes(head + fwd * 0.3 * hs + v(0, 0.25 * hs, 0), 0.6 * hs, 0.15 * hs, "head"),
    ]
    # A fan-shaped tail: flat, widening towards its end.
    tl = np.stack([tail0 + v(0, 0.1, 1) * p.tail_length * k for k in np.linspace(0, 1, 14)])
    wdt = np.linspace(0.25 * r, 0.6 * r, 14) * np.sqrt(np.clip(1 - np.linspace(-0.2, 1, 14) ** 8, 0.05, 1))
    parts.append(
        Part(
            "tail",
            tl,
            np.stack([wdt, np.full(14, 0.06 * r)], 1),
            np.asarray(Y),
            ["tail"],
            "hips",
            second,
            None,
            10,
        )
    )
    wings, legs = [], []
    for s, sx in SIDES:
        sh = v(sx * 0.6 * r, yb + 0.45 * r, -0.2 * L)
        el = sh + v(sx * 0.4 * W, 0.02 * W, 0.05 * W)
        hd = el + v(sx * 0.33 * W, 0.0, 0.06 * W)
        tip = hd + v(sx * 0.27 * W, 0.0, 0.14 * W)
        joints = sk.chain(
            [f"wing_upper_{s}", f"wing_lower_{s}", f"wing_hand_{s}"], np.stack([sh, el, hd]), "chest"
        )
        line = np.concatenate(
            [
                np.linspace(sh - v(sx * 0.5 * r, 0, 0), el, 8, endpoint=False),
                np.linspace(el, hd, 8, endpoint=False),
                np.linspace(hd, tip, 9),
            ]
        )
        x = np.linspace(0, 1, len(line))
        chord = 0.42 * L * (1 - 0.7 * x) * np.sqrt(np.clip(1 - x**6, 0.05, 1))
        parts.append(
            Part(
                f"wing_{s}",
                line,
                np.stack([chord, np.full(len(line), 0.05 * r) * (1 - 0.6 * x)], 1),
                np.asarray(Y),
                joints,
                "chest",
                second,
                None,
                12,
            )
        )
        wings.append((joints, sx))
        hip = v(sx * 0.35 * r, yb - 0.4 * r, 0.05 * L)
        knee, ankle = v(sx * 0.35 * r, 0.5 * H, 0.05 * L + 0.1 * H), v(sx * 0.35 * r, 0.08 * H, 0.05 * L)
        joints = sk.chain(
            [f"leg_upper_{s}", f"leg_lower_{s}", f"foot_{s}"], np.stack([hip, knee, ankle]), "hips"
        )
        parts.append(
            limb_part(
                f"leg_{s}",
                [hip, knee, ankle, v(sx * 0.35 * r, 0.03 * H, 0.05 * L - 0.5 * H)],
                0.12 * r,
                0.06 * r,
                joints,
                "hips",
                beak,
                n=16,
                segments=8,
            )
        )
        legs.append(Limb(tuple(joints), 0.0 if sx < 0 else 0.5, X, None, (-1.0, 0.0, 0.0)))

    def flap(b: ClipBuilder) -> None:
        for joints, sx in wings:
            up = (0.0, 0.0, sx)  # positive angle raises the wing on either side
            b.rotate(joints[0], up, 0.25 + 0.75 * b.wave(1))
            b.rotate(joints[1], up, 0.25 * b.wave(1, -0.12))
            b.rotate(joints[2], up, 0.2 * b.wave(1, -0.22))
        bob(b, "hips", 0.12 * r, cycles=1, offset=0.5)
        b.rotate("tail", X, 0.1 * b.wave(1))

    def idle(b: ClipBuilder) -> None:
        b.rotate("neck1", X, 0.12 * b.wave(2))
        b.rotate("head", Y, 0.5 * b.wave(1))
        b.rotate("tail", X, 0.15 * b.wave(3))
        for joints, sx in wings:
            b.rotate(joints[0], (0.0, 0.0, sx), -0.2 + 0.05 * b.wave(2))

    def walk(b: ClipBuilder) -> None:
        gait(b, legs, swing=0.35, lift=0.0, bend=0.6)
        b.rotate("neck1", X, 0.15 * b.wave(2))
        bob(b, "hips", 0.05 * r)
        for joints, sx in wings:
            b.rotate(joints[0], (0.0, 0.0, sx), np.full(b.frames, -0.2))

    return Body("bird", p, sk, parts, {"flap": (24, flap), "walk": (24, walk), "idle": (60, idle)})


# -- fish -------------------------------------------------------------------------------------
FISH = BodyParams(
    body_length=0.6, leg_length=0.0, neck_length=0.0, tail_length=0.2, head_size=0.1, girth=0.13
)


def build_fish(p: BodyParams, palette: tuple[np.ndarray, ...]) -> Body:
    main, second, belly = palette
    L, r, hs = p.body_length, p.girth, p.head_size
    y = 1.05 * r
    sk = SkeletonBuilder()
    spine = ["head", "spine1", "spine2", "spine3", "tail"]
    sk.chain(spine, np.stack([v(0, y, z * L) for z in (-0.3, -0.08, 0.12, 0.3, 0.45)]), None)
    n = 64
    line = np.stack([v(0, y, z) for z in np.linspace(-0.5 * L, 0.48 * L, n)])
    x = np.linspace(0, 1, n)
    # Fusiform: blunt head (fuller with a bigger head_size), thickest a third of the way, thin peduncle.
    head_fill = np.clip(hs / (0.8 * r), 0.6, 1.6)
    prof = np.sin(np.pi * np.clip(x, 0, 1) ** (0.55 / head_fill)) ** 0.8
    prof = np.maximum(prof, 0.12 * (x > 0.5))
    parts = [
        Part(
            "body", line, np.stack([0.5 * r * prof, r * prof], 1), np.asarray(Y), spine, None, main, belly, 28
        ),
        *eyes(v(0, y + 0.25 * r, -0.38 * L), 0.3 * r, 0.1 * r, "head"),
    ]
    fin_line = np.stack([v(0, y, z) for z in np.linspace(0.43 * L, 0.5 * L + p.tail_length, 16)])
    fx = np.linspace(0, 1, 16)
    fin_up = r * (0.15 + 0.95 * fx**0.8) * np.sqrt(np.clip(1 - np.clip(fx - 0.9, 0, None) / 0.1, 0.05, 1))
    parts.append(
        Part(
            "tail_fin",
            fin_line,
            np.stack([np.full(16, 0.04 * r), fin_up], 1),
            np.asarray(Y),
            ["tail"],
            "spine3",
            second,
            None,
            10,
        )
    )
    dorsal = np.stack([v(0, y + 0.75 * r, -0.02 * L), v(0, y + 1.45 * r, 0.1 * L)])
    parts.append(
        limb_part(
            "dorsal_fin",
            list(dorsal),
            0.18 * L,
            0.02 * L,
            ["spine1", "spine2"],
            None,
            second,
            up=(0, 0, -1),
            n=10,
            segments=10,
            flatten=1.0,
        )
    )
    parts[-1].radii[:, 0] = 0.03 * r  # thin across the body, long along it
    for s, sx in SIDES:
        root = v(sx * 0.3 * r, y - 0.35 * r, -0.2 * L)
        parts.append(
            limb_part(
                f"fin_{s}",
                [root, root + v(sx * 0.6 * r, -0.25 * r, 0.15 * L)],
                0.09 * L,
                0.02 * L,
                ["head"],
                None,
                second,
                up=Y,
                n=8,
                segments=10,
                flatten=0.15,
            )
        )

    def swim(b: ClipBuilder) -> None:
        sway(b, spine[1:], Y, 0.1, lag=0.14, grow=0.5)
        b.rotate("head", Y, -0.05 * b.wave(1, 0.1))

    def idle(b: ClipBuilder) -> None:
        sway(b, spine[1:], Y, 0.035, lag=0.14, grow=0.5)
        bob(b, "head", 0.08 * r, cycles=1)

    return Body("fish", p, sk, parts, {"swim": (30, swim), "idle": (60, idle)})


# -- snake ------------------------------------------------------------------------------------
SNAKE = BodyParams(
    body_length=2.0, leg_length=0.0, neck_length=0.0, tail_length=0.6, head_size=0.08, girth=0.055
)


def build_snake(p: BodyParams, palette: tuple[np.ndarray, ...]) -> Body:
    main, second, belly = palette
    L, r, hs = p.body_length, p.girth, p.head_size
    y = r
    nj = 16
    names = ["head"] + [f"spine{i:02d}" for i in range(1, nj)]
    zs = -0.5 * L + hs + np.arange(nj) * (L - hs) / nj
    sk = SkeletonBuilder()
    sk.chain(names, np.stack([v(0, y, z) for z in zs]), None)
    n = 128
    line = np.stack([v(0, y, z) for z in np.linspace(-0.5 * L + 0.5 * hs, 0.5 * L, n)])
    z = line[:, 2]
    taper = np.clip((0.5 * L - z) / max(p.tail_length, 1e-3), 0.04, 1.0) ** 0.7
    neck = 1.0 - 0.18 * np.exp(-(((z - (-0.5 * L + 2.2 * hs)) / (1.2 * hs)) ** 2))
    rad = r * taper * neck
    parts = [
        Part("body", line, np.stack([rad, 0.85 * rad], 1), np.asarray(Y), names, None, main, belly, 16),
        blob_part(
            "head",
            v(0, y, -0.5 * L + 2.3 * hs),
            v(0, y - 0.1 * hs, -0.5 * L - 0.2 * hs),
            0.75 * hs,
            0.5 * hs,
            ["head"],
            None,
            second,
            n=16,
            segments=16,
            taper=0.3,
        ),
        *eyes(v(0, y + 0.3 * hs, -0.5 * L + 0.6 * hs), 0.45 * hs, 0.1 * hs, "head"),
    ]

    def slither(b: ClipBuilder) -> None:
        sway(b, names[1:], Y, 0.28, lag=1.0 / 8)
        b.rotate("head", Y, 0.15 * b.wave(1, 0.3))

    def idle(b: ClipBuilder) -> None:
        # Raise the front of the body: tilt the head end up and lift the root by the drop that
        # tilting the first two segments about the head causes.
        b.rotate("head", X, np.full(b.frames, 0.5))
        b.rotate("spine02", X, np.full(b.frames, -0.5))
        lift = np.zeros((b.frames, 3))
        lift[:, 1] = 2 * (zs[1] - zs[0]) * np.sin(0.5)
        b.translate("head", lift)
        b.rotate("spine01", Y, 0.2 * b.wave(1))
        sway(b, names[4:], Y, 0.05, lag=1.0 / 10)

    return Body("snake", p, sk, parts, {"slither": (40, slither), "idle": (60, idle)})


# -- biped dinosaur ---------------------------------------------------------------------------
# body, leg, neck, tail length, head size, girth (BodyParams order)
DINOSAUR = BodyParams(1.0, 0.8, 0.3, 1.4, 0.28, 0.26)


def build_dinosaur(p: BodyParams, palette: tuple[np.ndarray, ...]) -> Body:
    sk = SkeletonBuilder()
    main, second, belly = palette
    L, H, r, hs = p.body_length, p.leg_length, p.girth, p.head_size
    ys = H + 0.15 * r
    sk.add("pelvis", v(0, ys, 0.25 * L))
    sk.add("spine", v(0, ys + 0.05 * r, -0.1 * L), "pelvis")
    sk.add("chest", v(0, ys, -0.42 * L), "spine")
    neck_dir = unit((0, 0.55, -0.85))
    n0 = v(0, ys + 0.3 * r, -0.5 * L)
    sk.chain(["neck", "head"], np.stack([n0, n0 + neck_dir * p.neck_length]), "chest")
    head = sk.position("head")
    fwd = unit((0, -0.15, -1))
    sk.add("jaw", head + v(0, -0.25 * hs, 0.1 * hs), "head")
    # The tail leaves the hips level and droops a little towards its tip.
    t0 = v(0, ys + 0.15 * r, 0.55 * L)
    tail_pts = [t0]
    for k in range(1, 6):
        tail_pts.append(tail_pts[-1] + unit((0, -0.05 - 0.04 * k, 1.0)) * p.tail_length / 5)
    tail = sk.chain([f"tail{k}" for k in range(1, 6)], np.stack(tail_pts[:5]), "pelvis")

    spine = [sk.position(j) for j in ("pelvis", "spine", "chest")]
    body_line = polyline([v(0, ys + 0.1 * r, 0.55 * L), *spine, v(0, ys + 0.15 * r, -0.58 * L)], 36)
    torso = _body_radii(36, 0.85 * r, 1.1 * r, 0.12)
    neck_pts = [v(0, ys + 0.1 * r, -0.4 * L), n0, head]
    tail_line = [v(0, ys + 0.1 * r, 0.4 * L), *tail_pts]
    jaw0, jaw1 = head + v(0, -0.3 * hs, 0.1 * hs), head + v(0, -0.35 * hs, -1.3 * hs)
    head0, head1 = head - fwd * 0.45 * hs, head + fwd * 1.55 * hs
    parts = [
        Part("body", body_line, torso, np.asarray(Y), ["pelvis", "spine", "chest"], None, main, belly, 24),
        limb_part("neck", neck_pts, 0.75 * r, 0.5 * hs, ["neck"], "chest", main, (0, 0.85, 0.55), 14, 16),
        blob_part("head", head0, head1, 0.5 * hs, 0.55 * hs, ["head"], "neck", main, Y, 20, 18, 0.35, belly),
        blob_part("jaw", jaw0, jaw1, 0.38 * hs, 0.2 * hs, ["jaw"], "head", belly, Y, 14, 14, 0.4),
        limb_part("tail", tail_line, 0.75 * r, 0.04 * r, tail, "pelvis", main, Y, 30, 14),
        *eyes(head + fwd * 0.2 * hs + v(0, 0.3 * hs, 0), 0.42 * hs, 0.09 * hs, "head"),
    ]
    legs, arms = [], []
    arm = 0.3 * L + 0.15 * H
    for s, sx in SIDES:
        x, z = sx * 0.55 * r, 0.25 * L
        hip, knee = v(x, ys - 0.1 * r, z), v(x, 0.52 * H, z - 0.16 * H)
        ankle, toe = v(x, 0.17 * H, z + 0.1 * H), v(x, 0.03 * H, z - 0.12 * H)
        joints = sk.chain([f"thigh_{s}", f"shin_{s}", f"foot_{s}"], np.stack([hip, knee, ankle]), "pelvis")
        pts = [v(x, ys + 0.25 * r, z + 0.1 * L), hip, knee, ankle, toe]
        parts.append(limb_part(f"leg_{s}", pts, 0.6 * r, 0.12 * r, joints, "pelvis", main, n=26))
        legs.append(Limb(tuple(joints), 0.0 if sx < 0 else 0.5, X, None, (-1.0, 0.0, 0.0)))
        sh = v(sx * 0.7 * r, ys - 0.35 * r, -0.4 * L)
        el = sh + unit((sx * 0.2, -0.8, -0.3)) * 0.5 * arm
        hand = el + unit((sx * 0.05, -0.2, -1.0)) * 0.35 * arm
        joints = sk.chain([f"upperarm_{s}", f"forearm_{s}"], np.stack([sh, el]), "chest")
        pts = [sh - v(sx * 0.2 * r, 0, 0), sh, el, hand, hand + unit((0, -0.6, -1)) * 0.15 * arm]
        parts.append(
            limb_part(f"arm_{s}", pts, 0.2 * r, 0.06 * r, joints, "chest", second, n=16, segments=10)
        )
        arms.append(joints)

    def walk(b: ClipBuilder) -> None:
        gait(b, legs, swing=0.45, lift=0.0, bend=0.8)
        sway(b, tail, Y, 0.08, lag=0.1)
        b.rotate("pelvis", Y, 0.04 * b.wave(1))
        b.rotate("neck", X, 0.05 * b.wave(2, 0.25))
        bob(b, "pelvis", 0.02 * H)

    def idle(b: ClipBuilder) -> None:
        b.rotate("neck", Y, 0.3 * b.wave(1))
        b.rotate("head", X, 0.1 * b.wave(2, 0.25))
        b.rotate("jaw", X, -0.2 * np.clip(b.wave(1, 0.5), 0.0, None))
        sway(b, tail, Y, 0.12, cycles=2, lag=0.1)
        for joints in arms:
            b.rotate(joints[1], X, 0.15 * b.wave(2))

    def roar(b: ClipBuilder) -> None:
        up = np.clip(b.wave(1), 0.0, None)
        b.rotate("chest", X, 0.1 * up)
        b.rotate("neck", X, 0.35 * up)
        b.rotate("jaw", X, -0.5 * up)
        sway(b, tail, X, 0.06, lag=0.1)

    return Body("dinosaur", p, sk, parts, {"walk": (36, walk), "idle": (60, idle), "roar": (40, roar)})
