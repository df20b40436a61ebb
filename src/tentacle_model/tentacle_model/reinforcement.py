"""
A segment's fibre reinforcement as bend and twist pseudo-moduli: a closed-form estimate.

Thesis chapter 4 reinforced a soft rod with a double helix of stiff fibre to raise its twisting
stiffness at little cost in bending; chapter 5 embedded a braid (Table 5.1: 5x in bending,
100x in twist). The model takes a segment's stiffness as pseudo-moduli on its section
(tentacle_spec: bending E I, twist E_twist J); a reinforcement adds what its fibres carry.

The estimate: fibres are truss members (axial load only, as in the thesis' FE model), the
helix they lie on keeps its radius R (the core holds it), strains are small. A fibre at angle
theta to the rod's axis is 1 / cos(theta) long per unit length of rod and strains

- R kappa cos(phi) cos^2(theta) under a curvature kappa (phi: where it is around the section;
  a helix visits every phi, so the square averages to one half),
- R tau sin(theta) cos(theta) under a twist rate tau,

so N fibres bonded in the matrix (helices: each layer wound on its own, the matrix between)
add, with A_f and I_f a fibre's area and second moment:

    dEI = N E_f A_f R^2 cos^3(theta) / 2 + N E_f I_f cos(theta)
    dGJ = N E_f A_f R^2 sin^2(theta) cos(theta)

(the second bending term: the fibres' own bending, small beside the first unless theta is
near 90 deg). A braid's yarns pass over and under each other and are tied only where they
cross: in bending both families stretch on one side and shorten on the other, which the braid
takes by scissoring (its angle changes at constant yarn length, as a finger trap does), so
the yarns carry no axial load and only their own bending is added; in twist one family
stretches while the other shortens, which scissoring cannot relieve: the truss term stands.
"""

from dataclasses import dataclass
import math

KINDS = ('helices', 'braid')


@dataclass(frozen=True)
class Reinforcement:
    """Fibres around a segment's axis, SI units."""

    kind: str                  # 'helices' (bonded layers) or 'braid' (interlaced yarns)
    fibres: int                # helices (in pairs: left- and right-handed) or braid yarns
    angle_rad: float           # the fibres' angle to the rod's axis, rad
    fibre_modulus_pa: float    # E_f, Pa
    fibre_diameter_m: float    # d, m
    radius_m: float            # R: of the helix the fibres' centrelines lie on, m

    def stiffness_n_m2(self):
        """Return (bending EI, twist GJ) the fibres add, N m^2."""
        c, s = math.cos(self.angle_rad), math.sin(self.angle_rad)
        d = self.fibre_diameter_m
        axial = self.fibres * self.fibre_modulus_pa * math.pi * d * d / 4   # N E_f A_f, N
        own = self.fibres * self.fibre_modulus_pa * math.pi * d ** 4 / 64 * c
        truss = axial * self.radius_m ** 2
        bend = own if self.kind == 'braid' else truss * c ** 3 / 2 + own
        return bend, truss * s * s * c


def pseudo_moduli(matrix_pa, second_moment_m4, polar_moment_m4, reinforcement):
    """
    Return (bend_1, bend_2, twist) pseudo-moduli, Pa, of a section reinforced.

    :param matrix_pa: the unreinforced (bend_1 about link z, bend_2 about link y, twist), Pa
    :param second_moment_m4: the section's (I about link y, I about link z), m^4
    :param polar_moment_m4: its J, m^4 (twist stiffness = twist pseudo-modulus x J)
    :param reinforcement: a Reinforcement, or None (the matrix alone)
    """
    if reinforcement is None:
        return tuple(matrix_pa)
    bend, twist = reinforcement.stiffness_n_m2()
    return (matrix_pa[0] + bend / second_moment_m4[1], matrix_pa[1] + bend / second_moment_m4[0],
            matrix_pa[2] + twist / polar_moment_m4)
