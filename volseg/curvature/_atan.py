"""The stencil kernels' angles: ``atan2(sqrt(s2), c) * sqrt(a2)``, the common case inline.

Each face of the weighted operator's stencil contributes its bending angle |psi| =
atan2(|N_a ^ N_b|, N_a . N_b) times its area (docs/design.md section 3; the kernel gives it
its sign by the side the far vertex lies on), 12 faces per voxel. Written as
``math.atan2(math.sqrt(s2), c) * math.sqrt(a2)``, the kernel spent half its time
there: glibc's `atan2` is correctly rounded, with slow paths, and two square roots
share the divider with it. `angle_times_root` does the same in one square root and,
for the faces of a smooth graph (an angle below 33 degrees), no reduction: atan(r) =
r (1 + z P(z) / Q(z)), z = r^2 = s2 / c^2, times sqrt(a2) is sqrt(s2 a2) / c
(1 + z P / Q). P / Q is Cephes' double `atan` (S. L. Moshier, the Cephes Math Library:
a 4/5 rational on [0, 0.66], the pi/4 shift above it), accurate near 0 where an
`arccos` form is not; a larger angle takes `atan2_upper`, Cephes reduced to the first
octant. Both are within 2 ulp of numpy's `arctan2` (tested) and exact at 0 (a flat
face's angle is 0).

`angle_times_root` is inlined in numba's IR at each of a kernel's 12 faces;
`atan2_upper`, the large angles' path, is a call. Inlined at every face too, it made
the weighted pass compile for 8.4-11.2 CPU-s (a third of a first run's compilation;
5.0-5.1 now) with no gain in speed: 256^3 takes 1.66-1.69 s now against 1.71-1.84
(best of 3, alternating runs). The values are the same bits.
"""

import math

import numba

_PI_2, _PI_4 = math.pi / 2, math.pi / 4
#: pi - fl(pi) in double: what the shifts by pi/4, pi/2 and pi add back.
_MOREBITS = 1.2246467991473532e-16
#: Cephes' bound of the unreduced rational (tan 33.4 degrees).
_SMALL = 0.66


@numba.njit(cache=True, nogil=True, inline="always")
def _atan_ratio(z):
    """P(z) / Q(z): atan(r) = r + r z P / Q for z = r^2, |r| <= 0.66."""
    p = ((((-8.750608600031904122785e-1 * z - 1.615753718733365076637e1) * z
           - 7.500855792314704667340e1) * z - 1.228866684490136173410e2) * z
         - 6.485021904942025371773e1)
    q = (((((z + 2.485846490142306297962e1) * z + 1.650270098316988542046e2) * z
           + 4.328810604912902668951e2) * z + 4.853903996359136964868e2) * z
         + 1.945506571482613964425e2)
    return p / q


@numba.njit(cache=True, nogil=True)   # a call: see the module docstring
def atan2_upper(y, x):
    """atan2(y, x) in [0, pi] for y >= 0 (not checked: the callers' y is a square root)."""
    ax = abs(x)
    hi, lo = max(y, ax), min(y, ax)
    if not hi > 0.0:                    # atan2(0, -0) is pi
        return math.pi if math.copysign(1.0, x) < 0.0 else 0.0
    # The first octant's angle: atan(lo / hi), or above 0.66 pi/4 + atan(r) with
    # r = (lo - hi) / (hi + lo).
    big = lo > _SMALL * hi
    r = (lo - hi) / (hi + lo) if big else lo / hi
    a = r + r * (r * r) * _atan_ratio(r * r)
    if big:
        a += _PI_4 + 0.25 * _MOREBITS
    if y > ax:
        a = (_PI_2 + 0.5 * _MOREBITS) - a
    if x < 0.0:
        a = (math.pi + _MOREBITS) - a
    return a


@numba.njit(cache=True, nogil=True, inline="always")
def angle_times_root(s2, c, a2):
    """atan2(sqrt(s2), c) * sqrt(a2) for s2, a2 >= 0 (module docstring); within a few
    ulp while s2 * a2 and c * c neither overflow nor underflow (in the kernels s2 + c^2
    = |N_a|^2 |N_b|^2 >= 1)."""
    cc = c * c
    if c > 0.0 and cc > 0.0 and s2 <= (_SMALL * _SMALL) * cc:
        z = s2 / cc
        return math.sqrt(s2 * a2) / c * (1.0 + z * _atan_ratio(z))
    return atan2_upper(math.sqrt(s2), c) * math.sqrt(a2)
