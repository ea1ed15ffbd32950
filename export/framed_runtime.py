"""FramedSimulator: a framed reduced model (anisofem.reduced.FramedModel, written by
`python -m export reduced --framed`) stepped by backward Euler with numpy alone.

The body is cut into D domains, each moving in its own rotating frame:

    x_i = R_d (y_i + U_i q_d) + c_d        for node i of domain d (held nodes stay put),

and a step minimizes, over the frames and the coordinates q,

    1/(2 dt^2) |x - x_hat|_M^2 + sum_d V_d(q_d) + V_joints(x) - f . x,

V_d the quartic energy of domain d's inner elements (c0, c1, C2, S3, W4 as in
runtime.ReducedSimulator), the inertia and loads through 3 x 3 moments of each domain's basis,
and the joints (the elements across domains or held nodes) element by element, StVK plus
fibers. The domains form a tree from the held nodes: a domain's centre is
c_e = c_p + R_p a_e + R_e b_e + t_e, so that a turn carries the domains beyond it. Newton's
unknowns per domain are (t_e, theta_e, q_e), R turned by exp([theta]); it starts from the
extrapolated state and stops where the next step, at the last step's rate of decrease, would
move no node more than STEP_TOLERANCE times the body's size. This is the library's step, in
the same order: the two agree to round-off.

    sim = FramedSimulator("t")                       # t.json + t.bin
    force = sim.masses[:, None] * (0.0, 0.0, -9.81)  # N per vertex, may change each step
    now = before = sim.rest_state()
    for _ in range(100):
        now, before = sim.step(now, before, force, dt=0.02), now
    x = sim.positions(now)                           # (n, 3), m

A state is a tuple (c (D, 3) m, R (D, 3, 3), q (Q,), base (3, 4)): base [R_g | c_g] carries
the held nodes rigidly, x = R_g x0 + c_g (step(..., base=) moves them: a hand, a character).
A file written with a display mesh (`--display`) moves the display's vertices, each a
weighted sum of the model's nodes (display_nodes, display_weights): forces are given and
positions returned on them. It needs numpy and runtime.py (copy both files together).
"""
import numpy as np

try:
    from .runtime import (MESH_ARRAYS, _angle_tag, _check_mesh, _in_range, _real, _same_mesh,
                          _triple_rows, checked, read_arrays)
except ImportError:  # copied next to runtime.py, outside the export package
    from runtime import (MESH_ARRAYS, _angle_tag, _check_mesh, _in_range, _real, _same_mesh,
                         _triple_rows, checked, read_arrays)

FRAMED_FORMAT = "anisofem-framed-1"
#: Newton's last step moves no node more than this share of the body's size (the library's).
STEP_TOLERANCE = 1e-8
#: [e_j]_x, the generators of rotations about the axes
GEN = np.array([[[0, 0, 0], [0, 0, -1], [0, 1, 0]],
                [[0, 0, 1], [0, 0, 0], [-1, 0, 0]],
                [[0, -1, 0], [1, 0, 0], [0, 0, 0]]], dtype=float)


#: a framed model's arrays (framed_arrays in export/writers/reduced.py): N model nodes, D
#: domains, Q coordinates in all, R the most in a domain, J joint elements of k nodes and p
#: points
FRAMED_ARRAYS = {
    "labels": ("int32", ("N",)), "Y": ("float64", ("N", 3)), "U": ("float64", ("N", 3, "R")),
    "r": ("int32", ("D",)), "centre": ("float64", ("D", 3)), "mass": ("float64", ("D",)),
    "a": ("float64", ("Q",)), "J": ("float64", ("D", 3, 3)), "A": ("float64", ("Q", 3, 3)),
    "B": ("float64", (None, 3, 3)), "radius": ("float64", ("D",)),
    "reach": ("float64", ("D",)), "c0": ("float64", ("D",)), "c1": ("float64", ("Q",)),
    "C2": ("float64", (None,)), "S3": ("float64", (None,)), "W4": ("float64", (None,)),
    "poly_offsets": ("int32", ("D", 3)), "parent": ("int32", ("D",)),
    "order": ("int32", ("D",)), "arm_parent": ("float64", ("D", 3)),
    "arm_own": ("float64", ("D", 3)), "chain": ("int32", ("P", 2)),
    "arms": ("float64", ("P", 3)), "joint_tets": ("int32", ("J", "k")),
    "joint_grads": ("float64", ("J", "p", "k", 3)), "joint_weights": ("float64", ("J", "p")),
    "mu": ("float64", ("J",)), "lam": ("float64", ("J",)), "kappa": ("float64", ("J",)),
    "fiber": ("float64", ("J", 3))}


def _check_framed(path, header, arrays, tag):
    """ValueError naming the file and the array unless the framed model's arrays (with the
    angle's tag) fit each other, the mesh's and the header's."""
    spec = {**MESH_ARRAYS, **{name + tag: kind for name, kind in FRAMED_ARRAYS.items()}}
    if "display_nodes" in arrays:
        spec.update({"display_nodes": ("int32", ("n", "dk")),
                     "display_weights": ("float64", ("n", "dk")),
                     "physics_rest": ("float64", ("N", 3))})
    sizes = checked(path, header, arrays, spec)
    r = arrays["r" + tag]
    if (r < 0).any() or (r > sizes["R"]).any() or r.sum() != sizes["Q"]:
        raise ValueError(f"path: {path}.json: array r{tag} ({r.tolist()}) does not fit the "
                         f"bases U{tag} ({sizes['R']} columns) and c1{tag} ({sizes['Q']})")
    if "display_nodes" not in arrays and sizes["N"] != sizes["n"]:
        raise ValueError(f"path: {path}.json: array labels{tag} has {sizes['N']} entries for "
                         f"{sizes['n']} vertices, and no display_nodes map a display mesh on them")
    _in_range(path, "labels" + tag, arrays["labels" + tag], -1, sizes["D"])
    _in_range(path, "joint_tets" + tag, arrays["joint_tets" + tag], 0, sizes["N"])
    _in_range(path, "parent" + tag, arrays["parent" + tag], -1, sizes["D"])
    _in_range(path, "order" + tag, arrays["order" + tag], 0, sizes["D"])
    _in_range(path, "chain" + tag, arrays["chain" + tag], 0, sizes["D"])
    if "display_nodes" in arrays:
        _in_range(path, "display_nodes", arrays["display_nodes"], 0, sizes["N"])
    if not isinstance(header.get("size"), (int, float)) or not header["size"] > 0:
        raise ValueError(f"path: {path}.json: the header's \"size\" (the body's size, m) is "
                         f"missing or not a positive number")
    _check_mesh(path, header, arrays)


class FramedSimulator:
    """A framed reduced model read from path.json + path.bin (module docstring). vertices
    (n, 3), tets (m, k): when given, the mesh the caller steps, refused unless it is the one
    the model was built for. angle: for a file of models at several fiber angles (`python -m
    export bake-reduced --framed`), the one to step, degrees."""

    def __init__(self, path, vertices=None, tets=None, angle=None):
        header, arrays = read_arrays(path)
        if header.get("model_format") != FRAMED_FORMAT:
            raise ValueError(f"path: {path}.json holds no framed model (model_format "
                             f"{header.get('model_format')!r}, expected {FRAMED_FORMAT!r}); "
                             f"rebuild it with `python -m export reduced SCENE --framed -o "
                             f"PATH`")
        tag = _angle_tag(header, angle)
        _check_framed(path, header, arrays, tag)
        _same_mesh(arrays, vertices, tets)
        self.header = header
        a = {k[:len(k) - len(tag)] if tag and k.endswith(tag) else k: np.array(v)
             for k, v in arrays.items() if not tag or k.endswith(tag) or "@" not in k}
        self.rest_positions, self.masses = a["rest_positions"], a["masses"]
        self.held, self.surface = a["held"].astype(bool), a["surface"]
        self.labels, self.Y, self.U = a["labels"].astype(np.int64), a["Y"], a["U"]
        self._x0 = a.get("physics_rest", self.rest_positions)   # the model's own nodes
        self._display = ((a["display_nodes"].astype(np.int64), a["display_weights"])
                         if "display_nodes" in a else None)
        self._domain_nodes = [np.flatnonzero(self.labels == e) for e in range(a["r"].size)]
        self.r = a["r"].astype(np.int64)
        self.q0 = np.concatenate([[0], np.cumsum(self.r)[:-1]]).astype(np.int64)
        self.z0 = np.concatenate([[0], np.cumsum(6 + self.r)[:-1]]).astype(np.int64)
        self.n_unknowns = int((6 + self.r).sum())
        self.centre, self.mass = a["centre"], a["mass"]
        self.a, self.J, self.A, self.B = a["a"], a["J"], a["A"], a["B"]
        self.radius, self.reach = a["radius"], a["reach"]
        self.polynomials = []
        for d, rd in enumerate(self.r):
            o = a["poly_offsets"][d]
            self.polynomials.append((
                float(a["c0"][d]), a["c1"][self.q0[d]:self.q0[d] + rd],
                a["C2"][o[0]:o[0] + rd * rd].reshape(rd, rd),
                a["S3"][o[1]:o[1] + rd ** 3].reshape(rd * rd, rd),
                a["W4"][o[2]:o[2] + rd * (rd + 1) * (rd + 2) // 6 * rd].reshape(-1, rd),
                _triple_rows(rd)))
        self.parent, self.order = a["parent"].astype(np.int64), a["order"].astype(np.int64)
        self.arm_parent, self.arm_own = a["arm_parent"], a["arm_own"]
        self.chain, self.arms = a["chain"].astype(np.int64), a["arms"]
        self.joint_nodes, local = np.unique(a["joint_tets"], return_inverse=True)
        self._local = local.reshape(a["joint_tets"].shape)              # in joint_nodes
        rows = (3 * self._local[:, :, None] + np.arange(3)).reshape(self._local.shape[0], -1)
        self._grad_index = rows.ravel()               # each element entry's place in (3 k,)
        self._plan_pairs()
        self.joint_grads, self.joint_weights = a["joint_grads"], a["joint_weights"]
        self.mu, self.lam, self.kappa = a["mu"], a["lam"], a["kappa"]
        self.fiber = a["fiber"]
        self.size = float(header["size"])
        self.zc = self.z0[:, None] + np.arange(3)
        self.zt = self.zc + 3
        self.zq = np.concatenate([np.arange(z + 6, z + 6 + rd)
                                  for z, rd in zip(self.z0, self.r)]).astype(np.int64)
        self.iterations = 0

    def _plan_pairs(self):
        """The joint nodes' pairs that share an element: each element Hessian entry's place
        among their 3 x 3 blocks (_pair_index), and the free pairs grouped by their nodes'
        domains (_pair_groups: (d, e, first nodes, second nodes, pair rows))."""
        m, n = self._local.shape
        k = self.joint_nodes.size
        keys = (self._local[:, :, None] * k + self._local[:, None, :]).ravel()
        unique, inverse = np.unique(keys, return_inverse=True)
        pair = inverse.reshape(m, n, 1, n, 1)
        self._pair_index = (9 * pair + 3 * np.arange(3)[None, None, :, None, None]
                            + np.arange(3)[None, None, None, None, :]).ravel()
        self._pairs = unique.size
        first, second = unique // k, unique % k
        d = self.labels[self.joint_nodes]
        domains = np.unique(d[d >= 0])
        self._pair_groups = []
        for e in domains:
            for f in domains:
                rows = np.flatnonzero((d[first] == e) & (d[second] == f))
                if rows.size:
                    self._pair_groups.append((int(e), int(f), first[rows], second[rows], rows))

    # -- states ----------------------------------------------------------------------------

    def rest_state(self):
        """The rest state: every frame at its rest centre, unturned, q = 0, the held nodes
        where they were built."""
        D = self.r.size
        return (self.centre.copy(), np.tile(np.eye(3), (D, 1, 1)), np.zeros(int(self.r.sum())),
                np.eye(3, 4))

    def positions(self, state):
        """Full positions (n, 3), m, of a state (of the display's vertices where it has one)."""
        if self._display is None:
            return self._positions(state, np.arange(self.labels.size))
        nodes, weights = self._display
        x = self._positions(state, nodes.ravel()).reshape(nodes.shape + (3,))
        return np.einsum("pk,pka->pa", weights, x)

    def _positions(self, state, nodes):
        """Positions (k, 3), m, of the model's nodes `nodes` (k,) in a state."""
        c, R, q, base = state
        d = self.labels[nodes]
        free = d >= 0
        x = self._x0[nodes] @ base[:, :3].T + base[:, 3]
        local = self.Y[nodes[free]].copy()
        for e in range(self.r.size):
            rows = d[free] == e
            local[rows] += self.U[nodes[free][rows], :, :self.r[e]] @ q[self.q0[e]:self.q0[e]
                                                                         + self.r[e]]
        x[free] = np.einsum("kab,kb->ka", R[d[free]], local) + c[d[free]]
        return x

    def project(self, force):
        """The moments (F0 (D, 3, 3), F (Q, 3, 3), Fsum (D, 3)) of nodal forces (n, 3), N (on
        the display's vertices where it has one: each spread over its model nodes by its
        weights)."""
        f = _real(force, "force", self.rest_positions.shape)
        if self._display is not None:
            nodes, weights = self._display
            spread = (weights[:, :, None] * f[:, None, :]).reshape(-1, 3)
            f = np.stack([np.bincount(nodes.ravel(), spread[:, a], self.labels.size)
                          for a in range(3)], axis=1)
        F0 = np.zeros((self.r.size, 3, 3))
        F = np.zeros((int(self.r.sum()), 3, 3))
        Fs = np.zeros((self.r.size, 3))
        for e in range(self.r.size):
            nodes = self._domain_nodes[e]
            F0[e] = f[nodes].T @ self.Y[nodes]
            F[self.q0[e]:self.q0[e] + self.r[e]] = np.einsum(
                "ka,kbr->rab", f[nodes], self.U[nodes, :, :self.r[e]])
            Fs[e] = f[nodes].sum(axis=0)
        return F0, F, Fs

    # -- the step --------------------------------------------------------------------------

    def step(self, now, before, force, dt, base=None, max_iter=50):
        """One backward-Euler step of dt s after the state `now` (`before` a step earlier, equal
        to now from rest), under nodal forces `force` (n, 3), N (all of them: gravity too);
        base (3, 4) [R_g | c_g]: where the held nodes are at the step's end, R_g x0 + c_g (a
        rigid motion carrying the body; default: where they are in now). Returns the next
        state; its Newton iterations are in self.iterations."""
        if not dt > 0:
            raise ValueError(f"dt: the time step must be > 0 s, got {dt}")
        base = now[3] if base is None else _rigid_motion(base)
        inertia = 1.0 / dt ** 2
        targets = self._targets(self.project(force), inertia, now, before)
        state = self._extrapolated(now, before, base)
        tolerance = STEP_TOLERANCE * self.size
        bound = np.inf
        for it in range(1, max_iter + 1):
            E, g, H, T = self._derivatives(state, targets, inertia)
            if not (np.isfinite(E) and np.isfinite(g).all() and np.isfinite(H).all()):
                raise FloatingPointError("step: the energy is not finite")
            dz = _descent(H, g)
            last, bound = bound, self._bound(T @ dz)
            if bound <= tolerance or (bound < last < np.inf and bound * bound / last
                                      <= tolerance):
                self.iterations = it
                return _orthonormal(self._retract(state, dz, 1.0))
            alpha, slope = 1.0, float(g @ dz)
            while True:
                trial = self._retract(state, dz, alpha)
                if self._energy(trial, targets, inertia) <= E + 1e-4 * alpha * slope:
                    break
                alpha *= 0.5
                if alpha * bound <= tolerance:
                    if bound <= 1e3 * tolerance:  # round-off: no decrease resolved
                        self.iterations = it
                        return state
                    raise FloatingPointError(f"step: the line search found no decrease "
                                             f"(step bound {bound:.3g} m)")
            state = trial
        raise FloatingPointError(f"step: {max_iter} Newton iterations spent (step bound "
                                 f"{bound:.3g} m)")

    def _targets(self, load, inertia, now, before):
        """The load's moments plus the inertia's pull towards x_hat = 2 x(now) - x(before)."""
        T0, T, t = (v.copy() for v in load)
        for (c, R, q, _), alpha in ((now, 2.0), (before, -1.0)):
            w = inertia * alpha
            for e in range(self.r.size):
                s = slice(self.q0[e], self.q0[e] + self.r[e])
                qe = q[s]
                T0[e] += w * R[e] @ (self.J[e] + np.einsum("a,aij->ij", qe, self.A[s]))
                Bd = self._B(e)
                T[s] += w * np.einsum("ij,bjk->bik", R[e], self.A[s].transpose(0, 2, 1)
                                      + np.einsum("a,abij->bij", qe, Bd))
                t[e] += w * self.mass[e] * c[e]
        return T0, T, t

    def _B(self, e):
        start = int((self.r[:e] ** 2).sum())
        rd = self.r[e]
        return self.B[start:start + rd * rd].reshape(rd, rd, 3, 3)

    def _pulled(self, q, T0, T):
        """(D, 3, 3) T0_d + sum_b q_b T_b over each domain's coordinates."""
        return T0 + np.add.reduceat(q[:, None, None] * T, self.q0)

    def _moment_energy(self, state, targets, inertia):
        """(the inertia and load terms' energy (module docstring), J; M (D, 3, 3), each
        domain's T0 + q . T)."""
        c, R, q, _ = state
        T0, T, t = targets
        M = self._pulled(q, T0, T)
        return (0.5 * inertia * (self.mass @ np.einsum("di,di->d", c, c) + 2 * self.a @ q
                                 + q @ q) - np.sum(R * M) - np.sum(t * c)), M

    def _energy(self, state, targets, inertia):
        q = state[2]
        E = self._moment_energy(state, targets, inertia)[0]
        for e, P in enumerate(self.polynomials):
            E += _quartic(P, q[self.q0[e]:self.q0[e] + self.r[e]])[0]
        x = self._positions(state, self.joint_nodes)
        return E + _elements(self, x, want=0)[0]

    def _derivatives(self, state, targets, inertia):
        """(energy, gradient (Z,), Hessian (Z, Z), Jacobian (Z, Z) of the free-centre unknowns
        in the tree's): the library's FramedModel._derivatives."""
        c, R, q, _ = state
        T0, T, t = targets
        Z = self.n_unknowns
        g, H = np.zeros(Z), np.zeros((Z, Z))
        E, M = self._moment_energy(state, targets, inertia)
        GR = np.einsum("jab,dbc->djac", GEN, R)                   # (D, 3, 3, 3)
        for e in range(self.r.size):
            zc, zt, rd = self.zc[e], self.zt[e], self.r[e]
            zq = np.arange(self.z0[e] + 6, self.z0[e] + 6 + rd)
            s = slice(self.q0[e], self.q0[e] + rd)
            g[zc] = inertia * self.mass[e] * c[e] - t[e]
            g[zt] = -np.einsum("jab,ab->j", GR[e], M[e])
            g[zq] = inertia * (self.a[s] + q[s]) - np.einsum("ab,kab->k", R[e], T[s])
            H[zc, zc] = inertia * self.mass[e]
            G2 = 0.5 * (np.einsum("iab,kbc->ikac", GEN, GR[e])
                        + np.einsum("kab,ibc->ikac", GEN, GR[e]))
            H[np.ix_(zt, zt)] = -np.einsum("ikab,ab->ik", G2, M[e])
            cross = -np.einsum("jab,kab->jk", GR[e], T[s])
            H[np.ix_(zt, zq)] = cross
            H[np.ix_(zq, zt)] = cross.T
            H[zq, zq] = inertia
            Ep, gp, Hp = _quartic(self.polynomials[e], q[s], derivatives=True)
            E += Ep
            g[zq] += gp
            H[np.ix_(zq, zq)] += Hp
        E += self._joint_derivatives(state, g, H)
        N = np.zeros((3 * self.r.size, Z))
        C = self.zc.ravel()
        for (f, d), arm in zip(self.chain, self.arms):
            w = R[f] @ arm
            if f != d:
                N[3 * d:3 * d + 3, self.zc[f]] += np.eye(3)
            N[3 * d:3 * d + 3, self.zt[f]] -= _cross(w)
            gc = g[self.zc[d]]
            H[np.ix_(self.zt[f], self.zt[f])] += (0.5 * (np.outer(gc, w) + np.outer(w, gc))
                                                  - (gc @ w) * np.eye(3))
        HN = H[:, C] @ N
        H = H + HN + HN.T + N.T @ (H[np.ix_(C, C)] @ N)
        g = g + N.T @ g[C]
        T = np.eye(Z)
        T[C] += N
        return E, g, H, T

    def _joint_derivatives(self, state, g, H):
        """Add the joints' gradient and Hessian, chained through each node's frame, to g and H;
        returns their energy."""
        c, R, q, _ = state
        nodes = self.joint_nodes
        x = self._positions(state, nodes)
        E, gx, He = _elements(self, x, want=2)
        blocks = np.bincount(self._pair_index, He.ravel(), 9 * self._pairs).reshape(-1, 3, 3)
        k = nodes.size
        d = self.labels[nodes]
        Jn = np.zeros((k, 3, 6 + self.r.max()))          # in each node's domain's unknowns
        for e in range(self.r.size):
            rows = np.flatnonzero(d == e)
            if rows.size == 0:
                continue
            z, rd = self.z0[e], self.r[e]
            w = x[rows] - c[e]                                         # (k_e, 3)
            G = gx[rows]
            V = np.einsum("ab,kbr->kar", R[e], self.U[nodes[rows], :, :rd])  # (k_e, 3, r)
            Jn[rows, :, :3] = np.eye(3)
            Jn[rows, :, 3:6] = -np.einsum("kj,jab->kab", w, GEN)
            Jn[rows, :, 6:6 + rd] = V
            g[z:z + 3] += G.sum(axis=0)
            g[z + 3:z + 6] += np.cross(w, G).sum(axis=0)
            GW = G.T @ w
            H[z + 3:z + 6, z + 3:z + 6] += 0.5 * (GW + GW.T) - np.trace(GW) * np.eye(3)
            g[z + 6:z + 6 + rd] += np.einsum("kar,ka->r", V, G)
            cr = np.cross(V.transpose(0, 2, 1), G[:, None, :]).sum(axis=0).T  # (3, r)
            H[z + 3:z + 6, z + 6:z + 6 + rd] += cr
            H[z + 6:z + 6 + rd, z + 3:z + 6] += cr.T
        # the Gauss-Newton part: sum over node pairs of Jn_i^T hess_ij Jn_j, by domain pairs
        for e, f, first, second, rows in self._pair_groups:
            ze, zf, ne, nf = self.z0[e], self.z0[f], 6 + self.r[e], 6 + self.r[f]
            right = (blocks[rows] @ Jn[second, :, :nf]).reshape(-1, nf)        # (3 p, nf)
            H[ze:ze + ne, zf:zf + nf] += Jn[first, :, :ne].reshape(-1, ne).T @ right
        return E

    def _retract(self, state, dz, alpha):
        c, R, q, base = state
        R2 = _rotations(alpha * dz[self.zt]) @ R
        return (self._centres(self._moves(state) + alpha * dz[self.zc], R2, base), R2,
                q + alpha * dz[self.zq], base)

    def _carried(self, c, R, base, e):
        """Where domain e's parent (the base for the held nodes) carries its pivot."""
        p = self.parent[e]
        if p < 0:
            return base[:, :3] @ self.arm_parent[e] + base[:, 3]
        return c[p] + R[p] @ self.arm_parent[e]

    def _moves(self, state):
        c, R, _, base = state
        return np.array([c[e] - self._carried(c, R, base, e) - R[e] @ self.arm_own[e]
                         for e in range(self.r.size)])

    def _centres(self, t, R, base):
        c = np.empty_like(t)
        for e in self.order:
            c[e] = self._carried(c, R, base, e) + R[e] @ self.arm_own[e] + t[e]
        return c

    def _extrapolated(self, now, before, base):
        R = _nearest_rotations(now[1] @ before[1].transpose(0, 2, 1) @ now[1])
        return (self._centres(2 * self._moves(now) - self._moves(before), R, base), R,
                2 * now[2] - before[2], base)

    def _bound(self, dz):
        q = np.sqrt(np.add.reduceat(dz[self.zq] ** 2, self.q0))
        return float(np.max(np.linalg.norm(dz[self.zc], axis=1)
                            + np.linalg.norm(dz[self.zt], axis=1) * self.radius
                            + q * self.reach))


def _quartic(P, q, derivatives=False):
    """The quartic c0 + c1.q + q C2 q / 2 + S3[q,q,q] + S4[q,q,q,q]: energy, and with
    derivatives its gradient and Hessian."""
    c0, c1, C2, S3, W4, triples = P
    r = q.size
    A = W4 @ q
    X = (A[triples].reshape(r * r, r) @ q).reshape(r, r)
    Y = (S3 @ q).reshape(r, r)
    E = c0 + c1 @ q + 0.5 * q @ C2 @ q + q @ Y @ q + q @ X @ q
    if not derivatives:
        return (E,)
    return E, c1 + (C2 + 3.0 * Y + 4.0 * X) @ q, C2 + 6.0 * Y + 12.0 * X


def _elements(sim, x, want):
    """The joint elements' StVK plus fiber energy (J) at their nodes' positions x (k, 3); with
    want >= 1 the gradient (k, 3), with want 2 the element Hessians (m, n, 3, n, 3)."""
    tets = sim._local
    G, w = sim.joint_grads, sim.joint_weights                       # (m, p, n, 3), (m, p)
    F = np.einsum("mna,mpnb->mpab", x[tets], G)
    E = 0.5 * (np.einsum("mpka,mpkb->mpab", F, F) - np.eye(3))
    trE = np.einsum("mpaa->mp", E)
    mu, lam, kappa = (v[:, None] for v in (sim.mu, sim.lam, sim.kappa))
    Fd = np.einsum("mpab,mb->mpa", F, sim.fiber)
    I4m1 = np.einsum("mpa,mpa->mp", Fd, Fd) - 1.0
    psi = 0.5 * lam * trE ** 2 + mu * np.einsum("mpab,mpab->mp", E, E) + kappa * I4m1 ** 2
    energy = float(np.sum(w * psi))
    if want == 0:
        return (energy,)
    S = (2 * mu[..., None, None] * E + (lam * trE)[..., None, None] * np.eye(3)
         + (4 * kappa * I4m1)[..., None, None] * np.einsum("ma,mb->mab", sim.fiber,
                                                             sim.fiber)[:, None])
    P = F @ S
    k = x.shape[0]
    grad = np.bincount(sim._grad_index, np.einsum("mp,mpab,mpnb->mna", w, P, G).ravel(),
                       3 * k).reshape(k, 3)
    if want == 1:
        return energy, grad
    Q = np.einsum("mpab,mpnb->mpna", F, G)                          # q_a = F G_a
    FF = F @ F.transpose(0, 1, 3, 2)
    GG = np.einsum("mpna,mpla->mpnl", G, G)
    GSG = np.einsum("mpna,mpab,mplb->mpnl", G, S, G)
    s = np.einsum("mpna,ma->mpn", G, sim.fiber)
    I = np.eye(3)
    He = (np.einsum("mpnl,ik->mpnilk", GSG, I)
          + mu[..., None, None, None, None] * np.einsum("mpli,mpnk->mpnilk", Q, Q)
          + mu[..., None, None, None, None] * np.einsum("mpik,mpnl->mpnilk", FF, GG)
          + lam[..., None, None, None, None] * np.einsum("mpni,mplk->mpnilk", Q, Q)
          + 8 * kappa[..., None, None, None, None]
          * np.einsum("mpi,mpk,mpn,mpl->mpnilk", Fd, Fd, s, s))
    return energy, grad, np.einsum("mp,mpnilk->mnilk", w, He)


def _descent(H, g):
    """-H^-1 g, by Cholesky, or with H's eigenvalues mirrored and floored at 1e-10 of the
    largest where H is not positive definite (the library's rule)."""
    try:
        L = np.linalg.cholesky(H)
    except np.linalg.LinAlgError:
        lam, V = np.linalg.eigh(H)
        lam = np.maximum(np.abs(lam), 1e-10 * np.abs(lam).max())
        return -V @ ((V.T @ g) / lam)
    return -np.linalg.solve(L.T, np.linalg.solve(L, g))


def _cross(w):
    """[w]_x (3, 3)."""
    return np.einsum("j,jab->ab", w, GEN)


def _rotations(theta):
    """exp([theta_d]_x) (D, 3, 3), Rodrigues' formula as the library writes it."""
    angle = np.linalg.norm(theta, axis=1)
    K = np.einsum("dj,jab->dab", theta, GEN)
    safe = np.where(angle > 0, angle, 1.0)
    first = np.where(angle > 0, np.sin(angle) / safe, 1.0)
    half = np.where(angle > 0, np.sin(0.5 * angle) / (0.5 * safe), 1.0)
    return np.eye(3) + first[:, None, None] * K + (0.5 * half ** 2)[:, None, None] * (K @ K)


def _nearest_rotations(R):
    u, _, vt = np.linalg.svd(R)
    return u @ vt


def _orthonormal(state):
    c, R, q, base = state
    return c, _nearest_rotations(R), q, base


def _rigid_motion(base):
    """base as a (3, 4) float64 [R | c], R a rotation to 1e-9; ValueError naming it otherwise."""
    base = _real(base, "base", (3, 4))
    R = base[:, :3]
    if not (np.abs(R @ R.T - np.eye(3)).max() < 1e-9 and np.linalg.det(R) > 0):
        raise ValueError("base: its first 3 columns must be a rotation (orthonormal, det 1)")
    return base
