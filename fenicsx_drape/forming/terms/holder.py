"""The blank holder as a nodal term: clamping on a surface and the friction bars of eq. 1.

A clamping surface of any shape (a rigid tool that answers ``gap(x, t)`` and
``covers(x, t)``; the paper's holder is :class:`FlatHolder`, the plane z = 0 outside a circular
opening) holds the sheet. Every node that the surface *covers* (its closest point is an
interior point of the surface: the node lies under it, not beyond its edge or opening) is
*under the holder*:

- **Clamping:** the node is held on the surface along its normal n = ∇φ by a two-sided
  penalty on the signed distance φ, ``f = −k φ n`` with the consistent stiffness
  ``K = k n⊗n + k φ ∇∇φ`` (N/mm; the same stiffness k as the tool contact,
  :mod:`fenicsx_drape.forming.terms.contact`). On the plane z = 0: ``f_z = −k z``.
- **Friction (eq. 1):** a perfectly plastic bar fixed at the node's initial position acts on
  it in the surface's tangent plane. The paper's bar has yield stress σ_y = F_tot μ / (A_f n_s),
  so it carries at most the force A_f σ_y = F_tot μ / n_s: the holding force times the
  friction coefficient, shared by the n_s nodes under the holder. As in the paper the bar lies
  along the node's *total* tangential displacement relative to the surface (not the slip
  velocity),

      u = x − X − d_tool(x; 0, t),  s = P u,  P = I − n⊗n,
      N = N(|s|) from the friction law,  f = −N s/|s|,

  with the law (``"paper_friction"``, :class:`~fenicsx_drape.materials.FrictionLaw`, or a
  user law of role ``"friction"``) elastic up to the slip ``holder_slip_mm`` and then
  perfectly plastic at N = F_tot μ / n_s; its sliding slip is committed with the step. The
  stiffness is consistent in x through s (with ∂s/∂x = P − (n·u) ∇∇φ − n ⊗ (∇∇φ u)); the
  tool's own displacement d_tool is taken as independent of x, which is exact for a holder
  that is fixed or translates. On the plane z = 0 the bar acts in x and y along the in-plane
  displacement, exactly the paper's.

``n_s`` follows the sheet as it draws in: the set of nodes under the holder, and n_s with it,
is re-evaluated from the converged positions after every step (so it lags by one step, which
keeps Newton's residual smooth within a step). A node that leaves the holder loses its bar.

**Force share** (the paper does not say how a symmetric model shares F_tot).
``force_N`` is the force the modelled part carries, and a node's share is its weight w in
n_s = Σ w:

- ``"symmetric_part"`` (default): the model is a symmetric part of the whole sheet and
  carries its share of the holding force (a quarter F/4, a half F/2;
  :func:`part_force_N`); nodes on a symmetry plane stand for half a node of the whole sheet,
  so they count w = ½ per plane and carry w times the force of an interior node; a quarter
  then reproduces the full sheet's force per node, F μ / n_s.
- ``"model"``: eq. 1 read for the model as built: the whole F is shared over the model's own
  nodes under the holder, every node counts one (a quarter's nodes each see about four times
  the force of the whole sheet's).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from fenicsx_drape.errors import ParameterError
from fenicsx_drape.forming.tools.shapes import FlatHolder
from fenicsx_drape.materials.base import MaterialLaw

__all__ = ["FORCE_SHARES", "BlankHolder", "FlatHolder", "StackHolder", "part_force_N"]

FORCE_SHARES = ("symmetric_part", "model")


def part_force_N(force_N: float, planes: int, force_share: str) -> float:
    """The holding force (N) carried by a model with ``planes`` symmetry planes.

    ``"symmetric_part"``: F / 2^planes (a quarter F/4); ``"model"``: the whole F.
    """
    check_force_share(force_share)
    return force_N / 2.0**planes if force_share == "symmetric_part" else force_N


def check_force_share(force_share: str, where: str = "[holder] holder_force_share") -> None:
    """Raise a :class:`ParameterError` unless ``force_share`` is a known reading of eq. 1."""
    if force_share not in FORCE_SHARES:
        raise ParameterError(f"{where} = {force_share!r}: choose \"symmetric_part\" (a symmetric "
                             "part carries its share of F; symmetry-plane nodes count ½) or "
                             "\"model\" (the whole F over the model's own nodes)")


def _tangent_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit tangents t₁, t₂ (n, 3) with (t₁, t₂, n) right-handed; e_x, e_y for n = e_z."""
    e = np.zeros_like(n)
    use_y = np.abs(n[:, 0]) > 0.9  # e_x too close to the normal: start from e_y
    e[~use_y, 0] = 1.0
    e[use_y, 1] = 1.0
    t1 = e - np.einsum("ni,ni->n", e, n)[:, None] * n
    t1 /= np.linalg.norm(t1, axis=1)[:, None]
    t2 = np.empty_like(t1)  # n × t₁, written out: np.cross costs more than the product here
    t2[:, 0] = n[:, 1] * t1[:, 2] - n[:, 2] * t1[:, 1]
    t2[:, 1] = n[:, 2] * t1[:, 0] - n[:, 0] * t1[:, 2]
    t2[:, 2] = n[:, 0] * t1[:, 1] - n[:, 1] * t1[:, 0]
    return t1, t2


class BlankHolder:
    """Clamping on a surface and eq. 1 friction bars under it (a :class:`NodalTerm`).

    Args:
        law: the friction bar's law (role ``"friction"``; force in N against slip in mm),
            e.g. ``model.laws()["friction"]``; its conditions ``holder_force_N`` and
            ``holder_nodes`` are set here, node by node and step by step.
        force_N: the holding force on the whole part (N; the case's ``[holder]
            holder_force_N``); the modelled part carries :attr:`part_force_N` of it, as
            ``force_share`` says.
        clamp_stiffness_N_per_mm: penalty stiffness ``k`` holding the nodes on the surface.
        surface: the clamping surface: ``gap(x, t)``, ``covers(x, t)`` and optionally
            ``displacement(x, t0, t1)`` (a tool of role holder).
        opening_radius_mm: instead of ``surface``: the paper's plates at z = 0 with a circular
            opening of this radius (:class:`FlatHolder`).
        symmetry_axes: coordinate axes normal to the model's symmetry planes (0 for x = 0,
            1 for y = 0): under ``"symmetric_part"`` nodes on them count with weight 1/2.
        force_share: ``"symmetric_part"`` or ``"model"`` (module docstring; the case file's
            default is the only default).
    """

    def __init__(self, law: MaterialLaw, *, force_N: float, force_share: str,
                 clamp_stiffness_N_per_mm: float, surface=None,
                 opening_radius_mm: float | None = None,
                 symmetry_axes: tuple[int, ...] = ()) -> None:
        if law.role != "friction":
            raise ParameterError(f"BlankHolder: the law {type(law).__name__} has role "
                                 f"{law.role!r}, expected 'friction'")
        if (surface is None) == (opening_radius_mm is None):
            raise ParameterError("BlankHolder: give either a clamping surface or "
                                 "opening_radius_mm (the flat holder), not both")
        for name, value in (("force_N", force_N),
                            ("clamp_stiffness_N_per_mm", clamp_stiffness_N_per_mm)):
            if not (np.isfinite(value) and value >= 0.0):
                raise ParameterError(f"BlankHolder: {name} = {value} must be finite and >= 0")
        if clamp_stiffness_N_per_mm <= 0.0:
            raise ParameterError("BlankHolder: clamp_stiffness_N_per_mm must be positive")
        check_force_share(force_share, "BlankHolder: force_share")
        self.law = law
        self.surface = surface if surface is not None else FlatHolder(float(opening_radius_mm))
        self.force_N = float(force_N)
        self.k_z = float(clamp_stiffness_N_per_mm)
        self.symmetry_axes = tuple(symmetry_axes)
        self.force_share = force_share

    @property
    def part_force_N(self) -> float:
        """The holding force the modelled part carries (:func:`part_force_N`)."""
        return part_force_N(self.force_N, len(self.symmetry_axes), self.force_share)

    @property
    def flat(self) -> bool:
        """Whether the clamping surface is a plane (then the holder's stiffness is symmetric)."""
        return bool(getattr(self.surface, "flat", False))

    def bind(self, X: np.ndarray, owned: np.ndarray, comm) -> None:
        """Reference positions, ownership and the communicator (for the global n_s)."""
        self.X = np.array(X, dtype=float)
        self.owned = np.asarray(owned, dtype=bool)
        self.comm = comm
        scale = max(np.abs(self.X[:, :2]).max(initial=0.0), 1.0)
        self.w = np.ones(len(self.X))
        if self.force_share == "symmetric_part":
            for axis in self.symmetry_axes:
                self.w[np.abs(self.X[:, axis]) < 1e-9 * scale] *= 0.5
        self.state = self.law.initial_state(len(self.X))  # the bars' history (sliding slip)
        self._trial: tuple[np.ndarray, float, np.ndarray] | None = None
        self._hold(self.X, 0.0)

    def _hold(self, x: np.ndarray, t: float) -> None:
        """Re-evaluate which nodes are under the holder and n_s (collective under MPI)."""
        self.under = np.asarray(self.surface.covers(x, t), dtype=bool)
        self.bars = np.flatnonzero(self.under)
        force, nodes = self._shares()
        self._law = dataclasses.replace(self.law, holder_force_N=force, holder_nodes=nodes)

    def _shares(self) -> tuple[np.ndarray, float]:
        """Each bar's holding force (N) and the n_s it is shared over (sets :attr:`n_s`)."""
        local = float(self.w[self.under & self.owned].sum())
        self.n_s = self.comm.allreduce(local) if self.comm is not None else local
        # A node on a symmetry plane is half a node.
        return self.part_force_N * self.w[self.bars], max(self.n_s, 1e-300)

    @property
    def yield_force_N(self) -> np.ndarray:
        """The force (N) at which each node under the holder slides (0 elsewhere)."""
        f_y = np.zeros(len(self.X))
        f_y[self.bars] = np.broadcast_to(self._law.yield_force_N, self.bars.shape)
        return f_y

    def _offset(self, bars: np.ndarray) -> float | np.ndarray:
        """How far from the surface (mm, along its normal) the given nodes are held: 0."""
        return 0.0

    def forces(self, x: np.ndarray, t: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Clamping and friction forces (N) and stiffness −∂f/∂x (N/mm) at positions ``x``."""
        n, b = len(x), self.bars
        f = np.zeros((n, 3))
        K = np.zeros((n, 3, 3))
        xb = x[b]
        g = self.surface.gap(xb, t)
        φ, nrm, H = g.phi - self._offset(b), g.normal, g.hessian
        f[b] = -self.k_z * φ[:, None] * nrm
        nn = nrm[:, :, None] * nrm[:, None, :]
        K[b] = self.k_z * (nn + φ[:, None, None] * H)
        # Friction bars along the total tangential displacement (eq. 1), in the tangent
        # basis (t₁, t₂) of the surface: e_x, e_y on the plane z = 0.
        u = xb - self.X[b]
        move = getattr(self.surface, "displacement", None)
        if move is not None:
            u = u - move(xb, 0.0, t)
        t1, t2 = _tangent_basis(nrm)
        u1, u2 = np.einsum("ni,ni->n", u, t1), np.einsum("ni,ni->n", u, t2)
        e = np.hypot(u1, u2)
        N, dN, state = self._law.update(e, dt, self.state[b])
        # N/e and the direction; at e → 0 the elastic bar is isotropic: N/e → dN/de.
        small = e < 1e-9 * getattr(self.law, "holder_slip_mm", 1.0)
        N_e = np.where(small, dN, N / np.where(small, 1.0, e))
        s = u1[:, None] * t1 + u2[:, None] * t2  # P u
        ŝ = s / np.where(small, 1.0, e)[:, None]
        ss = ŝ[:, :, None] * ŝ[:, None, :]
        P = np.eye(3) - nn
        f[b] += -N_e[:, None] * s
        K_s = N_e[:, None, None] * (P - ss) + dN[:, None, None] * ss  # ∂(−f)/∂s
        if H.any():  # a curved surface: the tangent plane turns with the node
            ds = P - np.einsum("ni,ni->n", nrm, u)[:, None, None] * H \
                - nrm[:, :, None] * np.einsum("nij,nj->ni", H, u)[:, None, :]
        else:
            ds = P
        K[b] += np.einsum("nik,nkj->nij", K_s, ds)
        new = self.state.copy()
        new[b] = state
        self._trial = (np.array(x, dtype=float), t, new)
        return f, K

    def commit(self) -> None:
        """Keep the bars' sliding, then let the set under the holder follow the sheet."""
        if self._trial is None:
            return
        x, t, self.state = self._trial
        self._trial = None
        self._hold(x, t)
        self.state[~self.under] = 0.0  # a node that left the holder has lost its bar

    def revert(self) -> None:
        """Forget the trial sliding of a step that is cut back."""
        self._trial = None


class StackHolder(BlankHolder):
    """The blank holder on a stack of plies (a :class:`NodalTerm`).

    Every ply under the holder is clamped at its own height in the flat stack: on the
    clamping surface offset along its normal by the ply's mid-plane height (the signed
    distance φ − z_k, with φ's normal and curvature). The eq. 1 friction bars act on the two
    outer plies, the ones the holder's plates touch, each with half the holding force shared
    over its own nodes under the holder (so the stack's holder friction is μ F, as one ply's);
    the inner plies' bars carry nothing and they are held in place by the inter-ply friction
    (:mod:`fenicsx_drape.fe.plies`). All plies go through one evaluation of the surface: a
    holder per ply cost the stack one surface search per ply and step.

    Args:
        law: the friction bars' law (see :class:`BlankHolder`).
        heights_mm: the plies' mid-plane heights, ply 1 (punch side) first.
        force_N, force_share, clamp_stiffness_N_per_mm, surface, symmetry_axes: as
            :class:`BlankHolder`'s.
    """

    def __init__(self, law: MaterialLaw, *, heights_mm, force_N: float, force_share: str,
                 clamp_stiffness_N_per_mm: float, surface,
                 symmetry_axes: tuple[int, ...] = ()) -> None:
        self.heights = np.asarray(heights_mm, dtype=float)
        if len(self.heights) < 2:
            raise ParameterError("StackHolder: a stack has two plies or more")
        super().__init__(law, force_N=force_N, force_share=force_share,
                         clamp_stiffness_N_per_mm=clamp_stiffness_N_per_mm, surface=surface,
                         symmetry_axes=symmetry_axes)

    def bind(self, X: np.ndarray, owned: np.ndarray, comm) -> None:
        """Each node's ply from its height in the flat stack, then :meth:`BlankHolder.bind`."""
        z = np.asarray(X, dtype=float)[:, 2:3]
        self.ply = np.argmin(np.abs(z - self.heights[None, :]), axis=1)
        super().bind(X, owned, comm)

    def _offset(self, bars: np.ndarray) -> np.ndarray:
        return self.heights[self.ply[bars]]

    def _shares(self) -> tuple[np.ndarray, np.ndarray]:
        """Half the part's force on each outer ply, over that ply's n_s; none on the rest."""
        plies = len(self.heights)
        mine = self.under & self.owned
        local = np.bincount(self.ply[mine], self.w[mine], minlength=plies)
        n_s = self.comm.allreduce(local) if self.comm is not None else local
        self.n_s = float(n_s[0])  # eq. 1's n_s of the punch-side ply
        force = np.zeros(plies)
        force[[0, -1]] = 0.5 * self.part_force_N
        k = self.ply[self.bars]
        return force[k] * self.w[self.bars], np.maximum(n_s[k], 1e-300)
