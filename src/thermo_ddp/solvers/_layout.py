"""The packing of the DDP's per-knot values and policies: one definition for Python and the C driver."""
from __future__ import annotations

import casadi as ca
import numpy as np


class Layout:
    """The packing of per-knot values and policies, defined here only: the symbolic knot functions, the numpy
    backend and the solver pack and read through it, and the C driver gets its sizes and offsets from it
    (``ddp_work_new``). value = [a; b; vec(Vxx)] (n_value), policy = [k; vec(K); pivot; d1; d2; stationarity]
    (n_policy; ``pivot`` is the offset of the four scalars), vec column-major as CasADi's."""

    SCALARS = ("pivot", "d1", "d2", "stationarity")

    def __init__(self, nx, nu):
        self.nx, self.nu = nx, nu
        self.n_value = 2 * nx + nx * nx
        self.pivot = nu + nu * nx
        self.n_policy = self.pivot + len(self.SCALARS)

    def c_sizes(self) -> tuple[int, int, int]:
        """(n_value, n_policy, pivot offset): the driver's view of the layout."""
        return self.n_value, self.n_policy, self.pivot

    def pack_policy(self, st):
        """A policy vector from a backward step's dict (CasADi or numpy)."""
        if isinstance(st["k"], np.ndarray):
            return np.concatenate([st["k"], st["K"].T.ravel(), [float(st[n]) for n in self.SCALARS]])
        return ca.vertcat(st["k"], ca.vec(st["K"]), *[st[n] for n in self.SCALARS])

    def pack_value(self, a, b, Vxx):
        if isinstance(a, np.ndarray):
            return np.concatenate([a, b, Vxx.T.ravel()])
        return ca.vertcat(a, b, ca.vec(Vxx))

    def unpack_value(self, S):
        """a, b, Vxx of a symbolic value vector."""
        nx = self.nx
        return S[:nx], S[nx: 2 * nx], ca.reshape(S[2 * nx:], nx, nx)

    def feedback(self, policy):
        """K (nu, nx) of one policy vector: symbolic, or a numpy row."""
        if isinstance(policy, np.ndarray):
            return policy[self.nu: self.pivot].reshape(self.nx, self.nu).T
        return ca.reshape(policy[self.nu: self.pivot], self.nu, self.nx)

    def gains(self, policy: np.ndarray):
        """k (N, nu) and K (N, nu, nx) from a policy array."""
        nx, nu = self.nx, self.nu
        k = policy[:, :nu].copy()
        K = policy[:, nu: self.pivot].reshape(-1, nx, nu).transpose(0, 2, 1).copy()
        return k, K

    def column(self, name: str) -> int:
        """The policy column of one of :attr:`SCALARS`."""
        return self.pivot + self.SCALARS.index(name)

    def costates(self, values: np.ndarray) -> np.ndarray:
        """Value gradients Vx = a + b at every knot, (N+1, nx)."""
        return values[:, : self.nx] + values[:, self.nx: 2 * self.nx]
