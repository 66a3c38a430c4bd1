"""Two more body plans: the horizontal biped dinosaur and the crab.

Same conventions as `zooctl.procedural.plans` (Y up, -Z forward, feet on y = 0, the animal's right
towards +X; ``palette`` is (main, secondary, belly) linear RGB). The dinosaur carries its body
level over two legs, balanced by a long tail, with a big head and small arms; the crab has a wide,
flat carapace on eight sprawling legs and two clawed arms in front.
"""

from __future__ import annotations

import numpy as np

from .body import Body, BodyParams, blob_part, limb_part
from .mesh import Part, polyline
from .motion import ClipBuilder, Limb, bob, gait, sway
from .plans import EYE, SIDES, X, Y, Z, _body_radii, _legged_walk, eyes, unit, v
from .skeleton import SkeletonBuilder

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
