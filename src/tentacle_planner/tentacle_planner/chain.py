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

import numpy as np
from tentacle_planner.dipoles import pairs_between_groups

MIN_LINK_FRACTION = 1e-6  # a partial link shorter than this fraction of its full length is dropped


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
    :param backbone_m: how far the backbone reaches past the base, m (0: retracted)
    :raises ValueError: inserted length outside [0, L], sublinks < 1, backbone_m < 0
    """
    total = spec.length_m
    inserted = total if inserted_m is None else float(inserted_m)
    if not np.isfinite(inserted) or inserted < 0 or inserted > total * (1 + 1e-12):
        raise ValueError(f'inserted length {inserted_m} m is outside [0, {total:g}] m')
    if int(sublinks) != sublinks or sublinks < 1:
        raise ValueError(f'sublinks {sublinks} must be a whole number >= 1')
    if not np.isfinite(backbone_m) or backbone_m < 0:
        raise ValueError(f'backbone position {backbone_m} m must be >= 0')
    inserted = min(inserted, total)
    s_base = total - inserted
    rows = []  # (start, length, segment, segment index)
    start = 0.0
    for index, segment in enumerate(spec.segments):
        h = segment.length_m / sublinks
        for k in range(int(sublinks)):
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
        # Joints within the backbone's reach (free arc length from the base) are stiffened.
        inside = (s_start - s_base) < backbone_m
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
