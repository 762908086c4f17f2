"""Penalty contact between sheet nodes and a rigid tool, as a nodal term.

With φ the signed gap of a node to the tool surface and n = ∇φ its outward normal
(:mod:`fenicsx_drape.forming.tools.shapes`), a node that penetrates (φ < 0) is pushed out along the
normal by a penalty force p(φ) ≥ 0,

    f_N = p(φ) n,          K_N = −∂f_N/∂x = −p'(φ) n⊗n − p(φ) ∇∇φ,

where the curvature term p ∇∇φ makes the Jacobian consistent on the curved punch (the force
turns with the normal). The penalty law is linear, p = k (−φ − δ/2), beyond a penetration
δ = f_s / k and quadratic, p = k φ² / (2δ), below it: the stiffness grows smoothly from zero
instead of jumping to k when a node touches, so a node that touches and leaves the tool
between Newton iterates does not make the residual jump (lightly pressed nodes on the die's
face did exactly that). Both regimes scale with the stiffness ``k`` (N/mm): the penetration at
a given force p is √(2 f_s p)/k below f_s/2 and (p + f_s/2)/k above, so it falls as 1/k.

**Choice of k.** The natural scale is the axial stiffness of one tow bar of a unit cell,
``n_t E_o / Δ = l_t E_o`` (n_t = l_t Δ tows of modulus E_o per tow over the length Δ), which
does not depend on Δ: 0.71 tows/mm × 3410 N/tow = 2.42 × 10³ N/mm for Table 2. The hemisphere
uses k = 0.3 l_t E_o = 726 N/mm (its case's ``penalty_factor``): its deepest penetration
at the end of forming is 0.020, 0.015 and 0.014 mm at Δ = 10, 5 and 2.5 mm, below 1 % of Δ
and 5 % of the ply thickness, while the stiffer k = l_t E_o costs 40 % more Newton iterations
on the finest mesh for results within 0.7° of shear. The smoothing force f_s = 100 N spreads
the onset over δ = f_s/k (0.14 mm); nodal contact forces are below about 1 N, in the
quadratic regime. ``demos/study_penalty.py`` shows the penetration falling as 1/k.

**Tool friction** (effect ``tool_friction``, beyond the paper, off by default): Coulomb
friction on the slip of the node relative to the tool over the step, regularised so that it
is smooth at zero slip,

    s = P (x − x_n − Δx_tool),  P = I − n⊗n,   f_T = −μ_t f_N s / √(|s|² + s_ε²),

with f_N = p(φ) the normal force and ``s_ε`` (mm) the regularising slip: below it the
friction force grows linearly with the slip (a stick stiffness μ_t f_N / s_ε). Δx_tool =
``tool.displacement(x, t_n, t)`` is how far the tool's material point under the node moved
over the step (a translation for the hemisphere's tools, any rigid motion for a meshed
tool); being rigid, it is affine in x, and its constant gradient (I − Q) enters the
Jacobian through ∂s/∂x = P Q − (n·d) ∇∇φ − n ⊗ (∇∇φ d), d = x − x_n − Δx_tool.

**Any tool** (``forming.tools``: closed form or meshed) answers ``gap(x, t)`` (φ, ∇φ, ∇∇φ)
and ``displacement(x, t0, t1)``. For a meshed tool φ is a C² spline
(:mod:`~fenicsx_drape.forming.tools.distance`), so force and Jacobian stay consistent and, without
friction, symmetric, as for the exact surfaces.
"""

from __future__ import annotations

import numpy as np

from fenicsx_drape.errors import ParameterError


def _outer(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a_i b_j node by node (n, 3, 3)."""
    return a[:, :, None] * b[:, None, :]


class PenaltyContact:
    """Penalty contact of the sheet's nodes with one rigid tool (a :class:`NodalTerm`).

    Args:
        tool: the rigid tool: ``gap(x, t)`` (signed gap, normal, curvature) and
            ``displacement(x, t0, t1)`` (its prescribed motion), e.g. a
            :class:`~fenicsx_drape.forming.tools.shapes.RevolvedTool` or ``MeshedTool``.
        stiffness_N_per_mm: penalty stiffness ``k`` per node (see the module docstring).
        friction: Coulomb coefficient μ_t of ``tool_friction`` (0 switches it off).
        slip_regularisation_mm: ``s_ε``, the slip below which friction is not yet at
            its Coulomb limit.
        smoothing_force_N: ``f_s``, the force below which the penalty law is quadratic.
    """

    def __init__(self, tool, stiffness_N_per_mm: float, *, friction: float = 0.0,
                 slip_regularisation_mm: float = 0.01, smoothing_force_N: float = 100.0) -> None:
        if not stiffness_N_per_mm > 0.0:
            raise ParameterError(f"contact with {tool.name}: penalty stiffness "
                                 f"{stiffness_N_per_mm} N/mm must be positive")
        if not friction >= 0.0:
            raise ParameterError(f"contact with {tool.name}: tool friction {friction} < 0")
        if not slip_regularisation_mm > 0.0:
            raise ParameterError(f"contact with {tool.name}: slip regularisation "
                                 f"{slip_regularisation_mm} mm must be positive")
        if not smoothing_force_N > 0.0:
            raise ParameterError(f"contact with {tool.name}: smoothing force "
                                 f"{smoothing_force_N} N must be positive")
        self.tool = tool
        self.k = float(stiffness_N_per_mm)
        self.δ = float(smoothing_force_N) / self.k
        self.μ = float(friction)
        self.s_ε = float(slip_regularisation_mm)
        self._x_n: np.ndarray | None = None  # positions at the last converged step
        self._t_n = 0.0
        self._trial: tuple[np.ndarray, float] | None = None
        # Where each node's gap was last evaluated (x, t, φ): a bound on the gap now.
        self._seen: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def bind(self, X: np.ndarray, owned: np.ndarray, comm) -> None:
        """Remember the reference positions (the slip of the first step starts there)."""
        self._x_n = np.array(X, dtype=float)
        self._t_n = 0.0

    def penalty(self, φ: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The normal force p(φ) ≥ 0 (N) and its slope p'(φ) (N/mm) at signed gaps φ (mm)."""
        k, δ = self.k, self.δ
        quadratic = φ > -δ
        p = np.where(quadratic, 0.5 * k / δ * np.minimum(φ, 0.0) ** 2, -k * (φ + 0.5 * δ))
        dp = np.where(quadratic, k / δ * np.minimum(φ, 0.0), -k)
        return p, dp

    def forces(self, x: np.ndarray, t: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Contact force (N) and stiffness −∂f/∂x (N/mm) at the positions ``x`` at time ``t``."""
        f, K = np.zeros((len(x), 3)), np.zeros((len(x), 3, 3))
        self._trial = (np.array(x, dtype=float), t)
        near = self._near(x, t)
        if not len(near):
            return f, K
        xs = x[near]
        g = self.tool.gap(xs, t)
        self._seen[0][near], self._seen[1][near], self._seen[2][near] = xs, t, g.phi
        p, dp = self.penalty(g.phi)
        n = g.normal
        f[near] = p[:, None] * n
        K[near] = -dp[:, None, None] * _outer(n, n) - p[:, None, None] * g.hessian
        active = g.phi < 0.0
        if self.μ > 0.0 and active.any():
            f_t, K_t = self._friction(xs, self._x_n[near], t, g, p, dp, active)
            f[near] += f_t
            K[near] += K_t
        return f, K

    def _near(self, x: np.ndarray, t: float) -> np.ndarray:
        """The nodes that may touch the tool at ``x``, ``t`` (all unless it bounds its motion).

        A node whose gap was φ' at x', t' has φ ≥ φ' − |x − x'| − (the tool's motion from t'
        to t); a node with φ > 0 feels no force (nor stiffness, nor friction).
        """
        moved = getattr(self.tool, "moved_mm", None)
        if self._seen is None or len(self._seen[0]) != len(x):
            self._seen = (np.array(x, dtype=float), np.full(len(x), t), np.full(len(x), -1.0))
        if moved is None:
            return np.arange(len(x))
        x_s, t_s, φ_s = self._seen
        bound = φ_s - np.linalg.norm(x - x_s, axis=1) - moved(t_s, t)
        return np.flatnonzero(~(bound > 0.0))

    def _friction(self, x, x_n, t, g, f_N, dp, active):
        n, H = g.normal, g.hessian
        d = x - x_n - self.tool.displacement(x, self._t_n, t)
        dn = np.einsum("ni,ni->n", d, n)
        s = d - dn[:, None] * n
        w = np.sqrt(np.einsum("ni,ni->n", s, s) + self.s_ε**2)
        m = s / w[:, None]
        f = -self.μ * f_N[:, None] * m
        # ∂s/∂x = P Q − (n·d) ∇∇φ − n ⊗ (∇∇φ d);  ∂m/∂s = (I − m⊗m) / w;  ∂f_N/∂x = p' n.
        P = np.eye(3) - _outer(n, n)
        Q = self._slip_gradient(t)
        ds = (P if Q is None else P @ Q) - dn[:, None, None] * H \
            - _outer(n, np.einsum("nij,nj->ni", H, d))
        dm = (np.eye(3) - _outer(m, m)) / w[:, None, None]
        K = self.μ * (f_N[:, None, None] * dm @ ds + dp[:, None, None] * _outer(m, n))
        on = active[:, None]
        return np.where(on, f, 0.0), np.where(on[:, :, None], K, 0.0)

    def _slip_gradient(self, t: float) -> np.ndarray | None:
        """Q = ∂(x − Δx_tool)/∂x (3, 3) over the step; None when it is the identity.

        A rigid motion makes Δx_tool affine in x, so Q follows from four evaluations.
        """
        probe = np.vstack([np.zeros(3), np.eye(3)])
        D = self.tool.displacement(probe, self._t_n, t)
        Q = np.eye(3) - (D[1:] - D[0]).T
        return None if np.array_equal(Q, np.eye(3)) else Q

    def project(self, x: np.ndarray, t: float) -> np.ndarray:
        """Predictor: nodes in contact at the last step keep their gap, others do not penetrate.

        A node pressed on the tool at the last converged step is moved along the normal to the
        same (negative) gap: an extrapolated position off the surface would leave the first
        Newton iteration without its contact stiffness (the quadratic penalty has none at
        φ ≥ 0), and the step would push it deep into the tool. Other nodes that
        penetrate are moved onto the surface.
        """
        g = self.tool.gap(x, t)
        φ_n = self.tool.gap(self._x_n, self._t_n).phi
        pressed = φ_n < 0.0
        move = np.where(pressed, g.phi - φ_n, np.minimum(g.phi, 0.0))
        return x - move[:, None] * g.normal

    def commit(self) -> None:
        """Accept the last positions as the start of the next step's slip."""
        if self._trial is not None:
            self._x_n, self._t_n = self._trial[0].copy(), self._trial[1]

    def revert(self) -> None:
        """Nothing to undo: the slip is measured from the last committed positions."""
        self._trial = None

    def penetration(self, x: np.ndarray, t: float) -> np.ndarray:
        """Penetration depth (mm, ≥ 0) of every node at time ``t``."""
        return np.maximum(-self.tool.gap(x, t).phi, 0.0)
