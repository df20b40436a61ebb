"""
The inserted part of a tentacle as a chain of rigid links joined by sprung joints.

Material coordinate s runs from the proximal end (0) to the tip (L). With ``inserted_m`` of
the rod pushed past the base, the free part is s in [L - inserted_m, L]; what is still behind
the base contributes nothing. Each segment is cut into ``sublinks`` equal links and the link
that straddles the base is cut there (a partial link).

Joint i sits at the proximal end of link i (joint 0 at the clamp). Its stiffness represents
the rod between the midpoints of links i-1 and i: compliances add,
1/k_i = (h_{i-1}/2)/EI_{i-1} + (h_i/2)/EI_i, and the clamp joint has only the second half.
This staggered (midpoint) scheme converges at second order in the link length.
"""

from dataclasses import dataclass
import math

import numpy as np
from tentacle_model.dipoles import pairs_between_groups

MIN_LINK_FRACTION = 1e-6  # a partial link shorter than this fraction of its full length is dropped
MAX_CHAIN_LINKS = 100_000
"""
The most links discretise() builds: the most any joint model solves (statics.MAX_LINKS).

The planar model is O(n) per Newton step: at this size a cold solve takes 0.05 to 3 s here
(2 cores; the slowest ran out of its 500 iterations) in an estimated 24 MiB, and building
the chain 0.5 s. Checked before any link is built, so a huge sublinks count is refused at
once.
"""


class ProblemTooLarge(ValueError):
    """A chain or a solve beyond the stated size limits; the message says which and why."""


@dataclass(frozen=True)
class Chain:
    """Arrays over the free links, base first (shape (n,) or (n, 3)); SI units."""

    lengths_m: np.ndarray          # (n,)
    stiffness_n_m: np.ndarray      # (n, 3) joint stiffness per radian: bend_1, bend_2, twist
    moments_a_m2: np.ndarray       # (n, 3) magnetic moment in the link frame
    masses_kg: np.ndarray          # (n,)
    s_start_m: np.ndarray          # (n,) material coordinate of each link's proximal end
    base_position_m: np.ndarray    # (3,)
    base_rotation: np.ndarray      # (3, 3)
    segment_index: np.ndarray = None  # (n,) the segment (one magnet) of each link; None:
    #                                   every link is a magnet of its own
    radii_m: np.ndarray = None     # (n,) radius of a circle of the section's area (None: 0)

    def interacting_pairs(self):
        """Return (i, j) index arrays of the link pairs in different segments (dipoles.py)."""
        groups = np.arange(self.size) if self.segment_index is None else self.segment_index
        return pairs_between_groups(groups)

    def interacting_pair_count(self):
        """Return how many pairs interacting_pairs() would give, without building them."""
        n = self.size
        if self.segment_index is None:
            return n * (n - 1) // 2
        counts = np.bincount(self.segment_index).astype(np.int64)
        return int((n * n - int(counts @ counts)) // 2)

    def contact_distances(self, pairs):
        """
        Return (p,) m: how close two magnets' centres may come before they touch.

        The sum of their radii; for links so short or so near along the rod that this is
        more than half their distance when straight, that half (a fold of over 120 degrees).
        """
        i, j = pairs
        centre = self.s_start_m + self.lengths_m / 2
        radii = np.zeros(self.size) if self.radii_m is None else self.radii_m
        return np.minimum(radii[i] + radii[j], 0.5 * np.abs(centre[j] - centre[i]))

    @property
    def size(self):
        """Return the number of links."""
        return len(self.lengths_m)


def discretise(spec, inserted_m=None, sublinks=1, backbone_m=0.0):
    """
    Return the Chain of the free part of a tentacle.

    :param spec: a TentacleSpec
    :param inserted_m: length pushed past the base, m (default: all of it)
    :param sublinks: links per segment, >= 1
    :param backbone_m: how far the backbone reaches past the base, m (0: retracted); more
        than 0 only for a tentacle with a backbone
    :raises ValueError: inserted length outside [0, L], sublinks < 1, backbone_m < 0, a
        backbone position for a tentacle without one
    :raises ProblemTooLarge: more than MAX_CHAIN_LINKS free links
    """
    total = spec.length_m
    inserted = total if inserted_m is None else float(inserted_m)
    if not np.isfinite(inserted) or inserted < 0 or inserted > total * (1 + 1e-12):
        raise ValueError(f'inserted length {inserted_m} m is outside [0, {total:g}] m')
    try:
        whole = int(sublinks) == sublinks
    except (TypeError, ValueError, OverflowError):  # inf, nan, not a number
        whole = False
    if not whole or sublinks < 1:
        raise ValueError(f'sublinks {sublinks} must be a whole number >= 1')
    sublinks = int(sublinks)
    if not np.isfinite(backbone_m) or backbone_m < 0:
        raise ValueError(f'backbone position {backbone_m} m must be >= 0')
    if backbone_m > 0 and spec.backbone is None:
        raise ValueError(f'backbone position {backbone_m:g} m given, but tentacle '
                         f'{spec.name!r} has no backbone (its file has no backbone: block)')
    inserted = min(inserted, total)
    s_base = total - inserted
    _check_link_count(spec, sublinks, s_base)
    rows = []  # (start, length, segment, segment index)
    start = 0.0
    for index, segment in enumerate(spec.segments):
        h = segment.length_m / sublinks
        # Links wholly behind the base are skipped by the test below; start just before the
        # first free one, so that the loop is as long as the chain it builds.
        first = min(sublinks, max(0, math.floor((s_base - start) / h) - 1))
        for k in range(first, sublinks):
            a, b = start + k * h, start + (k + 1) * h
            if b <= s_base:
                continue
            a_free = max(a, s_base)
            if b - a_free >= MIN_LINK_FRACTION * h:
                rows.append((a_free, b - a_free, segment, index))
        start += segment.length_m
    n = len(rows)
    lengths = np.array([r[1] for r in rows])
    s_start = np.array([r[0] for r in rows])
    bend = np.array([r[2].bend_stiffness_n_m2 for r in rows]).reshape(n, 3)
    if spec.backbone is not None and backbone_m > 0:
        # Links within the backbone's reach (free arc length from the base) are stiffened;
        # one that starts where the backbone ends is free, whatever the rounding of either.
        inside = (s_start - s_base) < backbone_m - 1e-9 * total
        bend[inside, :2] += spec.backbone.stiffness_n_m2
    half_compliance = (lengths / 2)[:, None] / bend
    compliance = half_compliance.copy()
    compliance[1:] += half_compliance[:-1]
    stiffness = 1.0 / compliance if n else np.zeros((0, 3))
    moments = np.array([r[2].magnetisation_a_per_m * r[2].area_m2 * r[1]
                        for r in rows]).reshape(n, 3)
    masses = np.array([r[2].density_kg_m3 * r[2].area_m2 * r[1] for r in rows])
    return Chain(lengths, stiffness, moments, masses, s_start, spec.base_position_m,
                 spec.base_rotation, np.array([r[3] for r in rows], dtype=int),
                 np.array([np.sqrt(r[2].area_m2 / np.pi) for r in rows]))


def _check_link_count(spec, sublinks, s_base):
    """Raise ProblemTooLarge if the free part would have more than MAX_CHAIN_LINKS links."""
    links, start = 0, 0.0
    for segment in spec.segments:
        free = min(max((start + segment.length_m - s_base) / segment.length_m, 0.0), 1.0)
        links += math.ceil(free * sublinks)  # at most one more than discretise keeps
        start += segment.length_m
    if links > MAX_CHAIN_LINKS:
        raise ProblemTooLarge(
            f'{sublinks} sublinks x {len(spec.segments)} segment(s) make {links} links, more '
            f'than the {MAX_CHAIN_LINKS} any joint model solves: use fewer sublinks')
