"""The arthropod body plans: insect, spider and crab, all on sprawling jointed legs (the
vertebrates are in `zooctl.procedural.vertebrates`).

Each ``build_<plan>(params, palette)`` lays out joints and parts for the given proportions in the
model convention (Y up, -Z forward, feet on y = 0, the animal's right towards +X) and attaches the
plan's clips. ``palette`` is (main colour, secondary colour, belly colour), linear RGB; the shared
pieces (axes, eyes) are in `zooctl.procedural.plan_parts`.
"""

from __future__ import annotations

import numpy as np

from .body import Body, BodyParams, blob_part, limb_part
from .mesh import Part
from .motion import ClipBuilder, Limb, bob, gait
from .plan_parts import EYE, SIDES, X, Y, Z, eyes, unit, v
from .skeleton import SkeletonBuilder


def sprawl_limb(joints: tuple[str, ...], phase: float, sx: float, direction: np.ndarray) -> Limb:
    """An insect or spider leg reaching out along ``direction``: it swings about the vertical and
    lifts about the horizontal axis across the leg."""
    return Limb(joints, phase, (0.0, sx, 0.0), tuple(unit(np.cross(direction, Y))), None)


# -- insect and spider ------------------------------------------------------------------------
INSECT = BodyParams(
    body_length=0.3, leg_length=0.25, neck_length=0.02, tail_length=0.0, head_size=0.05, girth=0.05
)
SPIDER = BodyParams(
    body_length=0.25, leg_length=0.35, neck_length=0.0, tail_length=0.0, head_size=0.075, girth=0.09
)


def _legged_walk(
    sk: SkeletonBuilder,
    parts: list[Part],
    origin: str,
    y: float,
    H: float,
    radius: float,
    attach: list[tuple[float, np.ndarray]],
    color: np.ndarray,
    first_leg_left_phase0: list[bool],
    thickness: float = 0.05,
) -> list[Limb]:
    """Add sprawling three-joint legs (side reach then down to the ground); returns their limbs.
    ``thickness``: the leg's radius at the body, times ``H`` (a third of it at the tip)."""
    limbs = []
    for i, ((zoff, direction), left0) in enumerate(zip(attach, first_leg_left_phase0, strict=True)):
        for s, sx in SIDES:
            d = unit(np.array([sx * direction[0], 0.0, direction[2]]))
            coxa = v(0, y, zoff) + d * radius
            knee = coxa + d * 0.4 * H + v(0, 0.35 * H, 0)
            foot = knee + d * 0.45 * H + v(0, 0.12 * H - knee[1], 0)
            tip = foot + d * 0.18 * H - v(0, 0.1 * H, 0)
            joints = sk.chain(
                [f"leg{i + 1}_upper_{s}", f"leg{i + 1}_lower_{s}", f"leg{i + 1}_foot_{s}"],
                np.stack([coxa, knee, foot]),
                origin,
            )
            parts.append(
                limb_part(
                    f"leg{i + 1}_{s}",
                    [coxa - d * 0.5 * radius, coxa, knee, foot, tip],
                    thickness * H,
                    0.3 * thickness * H,
                    joints,
                    origin,
                    color,
                    up=Y,
                    n=22,
                    segments=8,
                )
            )
            phase = 0.0 if (sx < 0) == left0 else 0.5
            limbs.append(sprawl_limb(tuple(joints), phase, sx, d))
    return limbs


def build_insect(p: BodyParams, palette: tuple[np.ndarray, ...]) -> Body:
    main, second, belly = palette
    L, H, r, hs = p.body_length, p.leg_length, p.girth, p.head_size
    y = 0.5 * H
    sk = SkeletonBuilder()
    sk.add("thorax", v(0, y, 0))
    sk.add("head", v(0, y + 0.2 * r, -0.2 * L - p.neck_length), "thorax")
    sk.add("abdomen", v(0, y + 0.1 * r, 0.15 * L), "thorax")
    head = sk.position("head")
    parts = [
        blob_part(
            "thorax",
            v(0, y, 0.2 * L),
            v(0, y, -0.22 * L),
            r,
            0.9 * r,
            ["thorax"],
            None,
            main,
            n=14,
            segments=16,
            belly=belly,
        ),
        blob_part(
            "abdomen",
            v(0, y + 0.05 * r, 0.1 * L),
            v(0, y + 0.25 * r, 0.85 * L),
            1.35 * r,
            1.2 * r,
            ["abdomen"],
            "thorax",
            second,
            n=22,
            segments=18,
            taper=-0.2,
            belly=belly,
        ),
        blob_part(
            "head",
            head + v(0, 0, 0.8 * hs),
            head - v(0, 0.1 * hs, 1.0 * hs),
            hs,
            0.95 * hs,
            ["head"],
            "thorax",
            main,
            n=14,
            segments=16,
        ),
        *eyes(head + v(0, 0.25 * hs, -0.55 * hs), 0.65 * hs, 0.3 * hs, "head"),
    ]
    for s, sx in SIDES:
        a0 = head + v(sx * 0.3 * hs, 0.7 * hs, -0.5 * hs)
        pts = [a0, a0 + unit((sx * 0.4, 0.8, -1)) * 0.12 * L, a0 + unit((sx * 0.6, 0.4, -1)) * 0.26 * L]
        joints = sk.chain([f"antenna1_{s}", f"antenna2_{s}"], np.stack(pts[:2]), "head")
        parts.append(
            limb_part(f"antenna_{s}", pts, 0.012 * L, 0.006 * L, joints, "head", EYE, up=Y, n=12, segments=6)
        )
    attach = [(-0.12 * L, unit((1, 0, -0.6))), (0.0, unit((1, 0, 0.0))), (0.12 * L, unit((1, 0, 0.7)))]
    limbs = _legged_walk(sk, parts, "thorax", y, H, 0.8 * r, attach, EYE * 2.5, [True, False, True])

    def walk(b: ClipBuilder) -> None:
        gait(b, limbs, swing=0.3, lift=0.35, bend=0.0)  # tripod gait
        b.rotate("abdomen", X, 0.04 * b.wave(2))
        bob(b, "thorax", 0.02 * H)
        for s, _ in SIDES:
            b.rotate(f"antenna1_{s}", X, 0.15 * b.wave(2))

    def idle(b: ClipBuilder) -> None:
        b.rotate("abdomen", X, 0.08 * b.wave(2))
        b.rotate("head", Y, 0.25 * b.wave(1))
        for s, sx in SIDES:
            b.rotate(f"antenna1_{s}", X, 0.25 * b.wave(3, 0.5 if sx > 0 else 0))
            b.rotate(f"antenna2_{s}", Y, 0.2 * b.wave(2))

    return Body("insect", p, sk, parts, {"walk": (24, walk), "idle": (60, idle)})


def build_spider(p: BodyParams, palette: tuple[np.ndarray, ...]) -> Body:
    main, second, belly = palette
    L, H, r, hs = p.body_length, p.leg_length, p.girth, p.head_size
    y = 0.35 * H
    sk = SkeletonBuilder()
    sk.add("cephalothorax", v(0, y, 0))
    sk.add("abdomen", v(0, y + 0.2 * r, 0.3 * L), "cephalothorax")
    parts = [
        blob_part(
            "cephalothorax",
            v(0, y, 1.1 * hs),
            v(0, y + 0.1 * hs, -1.2 * hs),
            1.0 * hs,
            0.7 * hs,
            ["cephalothorax"],
            None,
            main,
            n=16,
            segments=18,
            belly=belly,
        ),
        blob_part(
            "abdomen",
            v(0, y + 0.1 * r, 0.15 * L),
            v(0, y + 0.5 * r, 0.25 * L + 2.4 * r),
            1.05 * r,
            0.95 * r,
            ["abdomen"],
            "cephalothorax",
            second,
            n=22,
            segments=20,
            belly=belly,
        ),
        *eyes(v(0, y + 0.45 * hs, -0.95 * hs), 0.3 * hs, 0.16 * hs, "cephalothorax"),
    ]
    angles = np.radians([55.0, 20.0, -15.0, -50.0])
    attach = [(-0.3 * hs * np.sin(a), np.array([np.cos(a), 0.0, -np.sin(a)])) for a in angles]
    limbs = _legged_walk(
        sk, parts, "cephalothorax", y, H, 0.8 * hs, attach, main * 0.8, [True, False, True, False]
    )

    def walk(b: ClipBuilder) -> None:
        gait(b, limbs, swing=0.25, lift=0.3, bend=0.0)  # alternating tetrapod gait
        bob(b, "cephalothorax", 0.015 * H)
        b.rotate("abdomen", Y, 0.05 * b.wave(2))

    def idle(b: ClipBuilder) -> None:
        b.rotate("abdomen", X, 0.06 * b.wave(1))
        for lb in limbs[:2]:  # the front pair feels around
            b.rotate(lb.joints[0], lb.lift_axis, 0.25 + 0.2 * b.wave(2))

    return Body("spider", p, sk, parts, {"walk": (24, walk), "idle": (60, idle)})


# -- crab -------------------------------------------------------------------------------------
# body_length: carapace width (side to side); girth: carapace height; head_size: claw size.
CRAB = BodyParams(0.3, 0.2, 0.0, 0.0, 0.1, 0.07)


def build_crab(p: BodyParams, palette: tuple[np.ndarray, ...]) -> Body:
    main, second, belly = palette
    W, H, r, cs = p.body_length, p.leg_length, p.girth, p.head_size
    D = 0.68 * W  # depth front to back
    y = 0.42 * H
    sk = SkeletonBuilder()
    sk.add("body", v(0, y, 0))
    back, front = v(0, y - 0.1 * r, 0.5 * D), v(0, y + 0.1 * r, -0.5 * D)
    parts = [
        blob_part("carapace", back, front, 0.5 * W, 0.5 * r, ["body"], None, main, Y, 22, 24, 0.0, belly)
    ]
    for s, sx in SIDES:
        base = v(sx * 0.12 * W, y + 0.3 * r, -0.4 * D)
        top = base + v(sx * 0.03 * W, 0.45 * r + 0.04 * W, -0.05 * D)
        parts.append(limb_part(f"stalk_{s}", [base, top], 0.025 * W, 0.02 * W, ["body"], None, second, n=8))
    parts += eyes(v(0, y + 0.75 * r + 0.04 * W, -0.47 * D), 0.15 * W, 0.03 * W, "body")
    angles = np.radians([30.0, 8.0, -14.0, -36.0])
    attach = [(-0.3 * D * np.sin(a), np.array([np.cos(a), 0.0, -0.6 * np.sin(a)])) for a in angles]
    limbs = _legged_walk(sk, parts, "body", y, H, 0.42 * W, attach, second, [True, False, True, False], 0.1)
    claws = []
    for s, sx in SIDES:
        sh = v(sx * 0.3 * W, y, -0.35 * D)
        el = sh + unit((sx * 0.7, 0.3, -0.6)) * (0.15 * W + 0.6 * cs)
        wr = el + unit((-sx * 0.45, 0.1, -1.0)) * (0.1 * W + 0.6 * cs)
        tip = wr + unit((-sx * 0.5, 0.0, -1.0)) * 1.8 * cs
        fb = wr + unit((-sx * 0.6, -0.3, -1.0)) * 0.9 * cs
        joints = sk.chain(
            [f"claw_upper_{s}", f"claw_lower_{s}", f"claw_hand_{s}"], np.stack([sh, el, wr]), "body"
        )
        sk.add(f"claw_finger_{s}", fb, joints[-1])
        along = unit(tip - wr)
        arm_r = 0.04 * W + 0.2 * cs
        parts.append(limb_part(f"arm_{s}", [sh, el, wr], arm_r, 0.35 * cs, joints[:2], "body", main, n=16))
        pincer = (wr - along * 0.4 * cs, tip, 0.75 * cs, 0.55 * cs, [joints[2]], joints[1], main)
        parts.append(blob_part(f"pincer_{s}", *pincer, Y, 16, 14, 0.7))
        finger = ([fb, fb + along * 0.9 * cs], 0.2 * cs, 0.06 * cs, [f"claw_finger_{s}"], joints[2], EYE * 4)
        parts.append(limb_part(f"finger_{s}", *finger, n=10, segments=8))
        claws.append((joints, sx))

    def walk(b: ClipBuilder) -> None:
        gait(b, limbs, swing=0.22, lift=0.3, bend=0.0)
        bob(b, "body", 0.02 * H)
        for joints, sx in claws:
            b.rotate(joints[0], Y, sx * 0.1 * b.wave(1))

    def idle(b: ClipBuilder) -> None:
        b.rotate("body", Z, 0.03 * b.wave(1))
        for joints, sx in claws:
            b.rotate(joints[0], X, 0.2 * b.wave(1, 0.25 if sx > 0 else 0.0))
            b.rotate(f"claw_finger_{joints[0][-1]}", Y, sx * 0.3 * np.clip(b.wave(2), 0.0, None))

    def snap(b: ClipBuilder) -> None:
        for joints, sx in claws:
            b.rotate(joints[0], X, 0.5 * np.clip(b.wave(1), 0.0, None))
            b.rotate(joints[1], Y, -sx * 0.25 * b.wave(1, 0.1))
            b.rotate(f"claw_finger_{joints[0][-1]}", Y, sx * 0.35 * np.clip(b.wave(2), 0.0, None))

    return Body("crab", p, sk, parts, {"walk": (24, walk), "idle": (60, idle), "snap": (30, snap)})
