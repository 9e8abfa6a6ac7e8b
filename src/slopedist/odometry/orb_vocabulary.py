"""Train a small ORB vocabulary in DBoW2's text format (the ``ORBvoc.txt`` layout ORB-SLAM3 loads).

ORB-SLAM3 needs a bag-of-words vocabulary of ORB descriptors. The usual 139 MB ``ORBvoc.txt``
cannot be downloaded here, so this module builds one from the user's own frames: ORB features
(OpenCV, 256-bit rBRIEF as ORB-SLAM's), a hierarchical k-majority tree (DBoW2's k-medians for
binary descriptors, k-means++ seeding), and TF-IDF word weights.

Text layout (DBoW2 ``TemplatedVocabulary::loadFromTextFile``)::

    k L scoring weighting                  first line (scoring 0 = L1 norm, weighting 0 = TF-IDF)
    parent is_leaf d0 d1 ... d31 weight    one line per node, ids 1, 2, ... in this order

Usage::

    python -m slopedist.odometry.orb_vocabulary FRAME_DIR [FRAME_DIR ...] --out voc.txt
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from slopedist.core.errors import MissingInputError
from slopedist.core.paths import utf8_name

ORB_BYTES = 32
"""Bytes of one ORB descriptor (256 bits)."""


@dataclass
class _Node:
    parent: int
    descriptor: NDArray[np.uint8]
    children: list[int]
    members: NDArray[np.intp]
    depth: int
    weight: float = 0.0


def orb_descriptors(image_gray: NDArray[np.uint8], n_features: int = 1000) -> NDArray[np.uint8]:
    """ORB descriptors ``(N, 32)`` uint8 of one grey image (8 pyramid levels, scale 1.2)."""
    orb = cv2.ORB.create(nfeatures=n_features, scaleFactor=1.2, nlevels=8, fastThreshold=20)
    _, desc = orb.detectAndCompute(image_gray, None)
    return np.zeros((0, ORB_BYTES), np.uint8) if desc is None else np.asarray(desc, np.uint8)


def _hamming(bits_a: NDArray[np.float32], bits_b: NDArray[np.float32]) -> NDArray[np.float32]:
    """Hamming distances between rows of two 0/1 bit matrices ``(N, 256)``, ``(M, 256)``."""
    return np.asarray(
        bits_a.sum(1, keepdims=True) + bits_b.sum(1)[None, :] - 2.0 * bits_a @ bits_b.T
    )


def _k_majority(
    bits: NDArray[np.float32], k: int, rng: np.random.Generator, iterations: int = 8
) -> tuple[NDArray[np.float32], NDArray[np.intp]]:
    """Cluster binary rows into ``k`` groups: k-means++ seeds, then assign / bitwise majority."""
    n = bits.shape[0]
    centres = [bits[rng.integers(n)]]
    d2 = _hamming(bits, centres[0][None, :])[:, 0] ** 2
    for _ in range(1, k):
        total = d2.sum()
        idx = rng.integers(n) if total <= 0 else rng.choice(n, p=d2 / total)
        centres.append(bits[idx])
        d2 = np.minimum(d2, _hamming(bits, bits[idx][None, :])[:, 0] ** 2)
    C = np.stack(centres)
    assign = np.zeros(n, dtype=np.intp)
    for it in range(iterations):
        new = np.argmin(_hamming(bits, C), axis=1)
        if it and np.array_equal(new, assign):
            break
        assign = new
        for j in range(k):
            m = assign == j
            if m.any():
                C[j] = (bits[m].mean(axis=0) >= 0.5).astype(np.float32)
    return C, assign


def train_vocabulary(
    descriptors_per_image: list[NDArray[np.uint8]], k: int = 10, depth: int = 4, seed: int = 0
) -> list[_Node]:
    """Build the vocabulary tree; returns the nodes, root first, in DBoW2's id order."""
    if not descriptors_per_image or all(len(d) == 0 for d in descriptors_per_image):
        raise MissingInputError("no ORB features found to train a vocabulary from")
    desc = np.concatenate(descriptors_per_image)
    image_of = np.concatenate([np.full(len(d), i) for i, d in enumerate(descriptors_per_image)])
    bits = np.unpackbits(desc, axis=1).astype(np.float32)
    rng = np.random.default_rng(seed)
    nodes = [_Node(-1, np.zeros(ORB_BYTES, np.uint8), [], np.arange(len(desc)), 0)]
    queue = [0]
    while queue:  # breadth first, so a parent's id is always smaller than its children's
        nid = queue.pop(0)
        node = nodes[nid]
        if node.depth == depth or len(node.members) <= 1:
            continue
        member_bits = bits[node.members]
        if len(node.members) <= k:
            centres, assign = member_bits, np.arange(len(node.members))
        else:
            centres, assign = _k_majority(member_bits, k, rng)
        for j in range(centres.shape[0]):
            members = node.members[assign == j]
            if members.size == 0:
                continue
            packed = np.packbits(centres[j].astype(np.uint8))
            nodes.append(_Node(nid, packed, [], members, node.depth + 1))
            node.children.append(len(nodes) - 1)
            queue.append(len(nodes) - 1)
    n_images = len(descriptors_per_image)
    for node in nodes[1:]:
        if not node.children:  # a word: TF-IDF weight log(N / images containing it)
            node.weight = math.log(n_images / len(np.unique(image_of[node.members])))
    return nodes


def write_vocabulary(nodes: list[_Node], path: str | Path, k: int, depth: int) -> Path:
    """Write the tree in DBoW2's text layout (no trailing newline: DBoW2's reader would take an
    empty last line for a node)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = [f"{k} {depth} 0 0"]
    for node in nodes[1:]:
        leaf = 0 if node.children else 1
        desc = " ".join(str(int(b)) for b in node.descriptor)
        lines.append(f"{node.parent} {leaf} {desc} {node.weight:.6g}")
    path.write_text("\n".join(lines))
    return path


def images_in(folders: Iterable[str | Path], every: int = 1) -> list[Path]:
    """Image files (png/jpg) of the given folders, sorted, taking every ``every``-th."""
    files: list[Path] = []
    for folder in folders:
        found = sorted(
            p for p in Path(folder).iterdir() if p.suffix.lower() in (".png", ".jpg", ".jpeg")
        )
        if not found:
            raise MissingInputError(f"no images in {folder}")
        files += found[::every]
    return files


def train_from_images(
    paths: list[Path], out: str | Path, k: int = 10, depth: int = 4, n_features: int = 1000
) -> Path:
    """ORB features of every image → vocabulary file ``out``."""
    descs = []
    for p in paths:
        with utf8_name(p) as name:
            image = cv2.imread(name, cv2.IMREAD_GRAYSCALE)
        if image is not None:
            descs.append(orb_descriptors(np.asarray(image, np.uint8), n_features))
    return write_vocabulary(train_vocabulary(descs, k, depth), out, k, depth)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Train a DBoW2 text ORB vocabulary.")
    parser.add_argument("folders", nargs="+", type=Path)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--k", type=int, default=10, help="branching factor")
    parser.add_argument("--depth", type=int, default=4, help="levels (k**depth words at most)")
    parser.add_argument("--every", type=int, default=1, help="use every n-th image")
    args = parser.parse_args(argv)
    path = train_from_images(images_in(args.folders, args.every), args.out, args.k, args.depth)
    print(f"wrote {path}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
