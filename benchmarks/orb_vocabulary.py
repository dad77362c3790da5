"""A bag-of-binary-words vocabulary for ORB-SLAM3, trained here (the side-by-side benchmark's one missing piece).

ORB-SLAM2/3 load a DBoW2 vocabulary at start (``ORBvoc.txt``, 139 MB, trained by its authors on the Bovisa
images); it is not on PyPI and this machine cannot reach GitHub, so `benchmarks/orbslam3_side.py` trains one the way
DBoW2 does (Galvez-Lopez & Tardos 2012): hierarchical k-medians on ORB descriptors under the Hamming distance, ``k``
children per node, ``L`` levels, each centre the bitwise majority of its cluster, k-means++ seeding; the leaves are
the words, weighted by their inverse document frequency over the training images (TF-IDF, L1 scoring: the official
file's header ``10 6 0 0``). Written in DBoW2's text format::

    k L scoring weighting
    parent_id is_leaf d0 d1 ... d31 weight      (one line per node after the root, parents before children)

The benchmark takes the official file's shape (k 10, L 6): ORB-SLAM3 groups features for its BoW matching (the
reference keyframe, and the pairs local mapping triangulates) under the nodes of level L - 4, 100 of them at L 6. A
tree one level shallower groups them under 10 nodes, and ORB-SLAM3's monocular maps were then much worse
(`benchmarks/results/orbslam3_side_vocab_L5.md`). Trained on far fewer descriptors than the authors' (about 2 x 10^5),
most leaves hold one or two; what that costs ORB-SLAM3 is said beside its results (docs/localization.md).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

_POP = np.array([bin(i).count("1") for i in range(256)], np.uint8)  # bits set in each byte value


def hamming_to(desc: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """(n, m) Hamming distances between ``desc`` (n, 32) uint8 and ``centres`` (m, 32) uint8."""
    out = np.empty((len(desc), len(centres)), np.int32)
    for j, c in enumerate(centres):
        out[:, j] = _POP[np.bitwise_xor(desc, c)].sum(axis=1, dtype=np.int32)
    return out


def majority(desc: np.ndarray) -> np.ndarray:
    """The bitwise majority of binary descriptors (n, 32) uint8: DBoW2's mean of ORB descriptors (ties: 0)."""
    bits = np.unpackbits(desc, axis=1)
    return np.packbits(2 * bits.sum(axis=0, dtype=np.int64) > len(desc)).astype(np.uint8)


def k_medians(desc: np.ndarray, k: int, rng: np.random.Generator, iterations: int = 10) -> np.ndarray:
    """Cluster labels (n,) of binary descriptors into ``k`` clusters: k-means++ seeds, then Hamming assignment and
    majority centres until the labels stop changing (at most ``iterations``)."""
    n = len(desc)
    centres = [desc[rng.integers(n)]]
    d = hamming_to(desc, np.array(centres))[:, 0].astype(np.float64)
    for _ in range(1, k):
        p = d**2
        if p.sum() == 0:  # fewer distinct descriptors than k
            break
        centres.append(desc[rng.choice(n, p=p / p.sum())])
        d = np.minimum(d, hamming_to(desc, centres[-1][None])[:, 0])
    C = np.array(centres)
    labels = np.full(n, -1)
    for _ in range(iterations):
        new = np.argmin(hamming_to(desc, C), axis=1)
        if np.array_equal(new, labels):
            break
        labels = new
        C = np.array([majority(desc[labels == j]) if np.any(labels == j) else C[j] for j in range(len(C))])
    return labels


def train(images: Sequence[np.ndarray], k: int = 10, levels: int = 6, seed: int = 0) -> dict:
    """A vocabulary from the ORB descriptors of each training image (``images``: one (n_i, 32) uint8 array each).
    Returns ``parent``, ``leaf``, ``desc`` (one per node, the root first, parents before children: breadth first) and
    ``weight`` (the leaves' inverse document frequency, 0 elsewhere)."""
    if not 2 <= k <= 20 or not 1 <= levels <= 10:
        raise ValueError(f"DBoW2 takes 2 <= k <= 20 and 1 <= L <= 10, not k {k}, L {levels}")
    rng = np.random.default_rng(seed)
    desc = np.concatenate([np.asarray(d, np.uint8).reshape(-1, 32) for d in images])
    doc = np.concatenate([np.full(len(d), i) for i, d in enumerate(images)])
    parent, depth, members = [-1], [0], [np.arange(len(desc))]
    centre = [np.zeros(32, np.uint8)]
    children: list[list[int]] = [[]]
    q = 0
    while q < len(parent):  # breadth first: a node's children get the next ids
        idx = members[q]
        if depth[q] < levels and len(idx) > k:
            labels = k_medians(desc[idx], k, rng)
            for j in np.unique(labels):
                sub = idx[labels == j]
                parent.append(q)
                depth.append(depth[q] + 1)
                members.append(sub)
                centre.append(majority(desc[sub]))
                children.append([])
                children[q].append(len(parent) - 1)
        q += 1
    leaf = np.array([not c for c in children])
    leaf[0] = False
    weight = np.zeros(len(parent))
    n_docs = len(images)
    for i in np.flatnonzero(leaf):
        weight[i] = np.log(n_docs / len(np.unique(doc[members[i]])))
    return {"k": k, "levels": levels, "parent": np.array(parent), "leaf": leaf, "desc": np.array(centre),
            "weight": weight}


def write_text(voc: dict, path: str | Path) -> Path:
    """DBoW2's text format (``TemplatedVocabulary::loadFromTextFile``): the header, then the nodes after the root.
    No newline after the last node: DBoW2 reads lines until end of file and would make an empty one a node."""
    lines = [f"{voc['k']} {voc['levels']} 0 0"]  # L1 scoring, TF-IDF weighting
    for i in range(1, len(voc["parent"])):
        d = " ".join(str(int(b)) for b in voc["desc"][i])
        lines.append(f"{voc['parent'][i]} {int(voc['leaf'][i])} {d} {voc['weight'][i]:.6g}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".part")
    tmp.write_text("\n".join(lines))
    tmp.replace(path)
    return path


def read_text(path: str | Path) -> dict:
    """The vocabulary back from its text file (the checks' and the tests' reader; ORB-SLAM3 has its own)."""
    rows = Path(path).read_text().split("\n")
    k, levels, scoring, weighting = (int(v) for v in rows[0].split())
    vals = np.array([r.split() for r in rows[1:]], dtype=float).reshape(len(rows) - 1, 35)
    return {"k": k, "levels": levels, "scoring": scoring, "weighting": weighting,
            "parent": np.r_[-1, vals[:, 0].astype(int)], "leaf": np.r_[False, vals[:, 1] > 0],
            "desc": np.vstack([np.zeros(32, np.uint8), vals[:, 2:34].astype(np.uint8)]),
            "weight": np.r_[0.0, vals[:, 34]]}
