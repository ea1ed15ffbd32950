// Step a baked scene's framed model (python -m export bake-reduced --framed) in plain
// JavaScript: the browser's side of export/framed_runtime.py's FramedSimulator. The body is
// cut into domains, each moving in its own rotating frame, x_i = R_d (y_i + U_i q_d) + c_d;
// a step is Newton over each domain's own move t, turn theta and coordinates q (the domains'
// centres carried along their kinematic tree), on the exact energy: each domain's quartic,
// the inertia and loads through 3 x 3 moments, and the joint elements (StVK plus fibers).
// A state's base (12 numbers, [R_g | c_g] row by row) carries the held vertices rigidly,
// x = R_g x0 + c_g: a step may move it (a hand, a character).
import { cholesky, choleskySolve, dot, quartic } from "./reduced.js";

const STEP_TOLERANCE = 1e-8;
const MAX_ITER = 50;
const ARMIJO = 1e-4;

// The framed model of a scene at one fiber angle: the interface of stepper.js's Simulation
// (n, dt, x, steps, reset, step, setFiberAngle, fiberAngle), and r, validation.
export class FramedSimulation {
  constructor(scene, fiberAngle) {
    this.header = scene.header;
    this.arrays = scene.arrays;
    this.n = this.header.n;
    this.dt = this.header.dt;
    this.size = this.header.size;
    const masses = this.arrays.masses.data;
    this.gravity = new Float64Array(3 * this.n);
    for (let i = 0; i < this.n; i++) {
      for (let c = 0; c < 3; c++) this.gravity[3 * i + c] = masses[i] * this.header.gravity[c];
    }
    this.setFiberAngle(fiberAngle);
  }

  setFiberAngle(angle) {
    const tag = `@${angle}`;
    if (!(`W4${tag}` in this.arrays)) throw new Error(`framed model: no fiber angle ${angle}`);
    const get = (name) => this.arrays[name + tag];
    this.fiberAngle = angle;
    this.validation = this.header.validation[this.header.fiber_angles.indexOf(angle)];
    const m = {};
    for (const name of ["labels", "Y", "U", "centre", "mass", "a", "J", "A", "B", "radius",
                        "reach", "c0", "c1", "C2", "S3", "W4", "poly_offsets", "parent",
                        "order", "arm_parent", "arm_own", "chain", "arms", "joint_grads",
                        "joint_weights", "mu", "lam", "kappa", "fiber"]) {
      m[name] = get(name).data;
    }
    m.rs = Array.from(get("r").data);
    m.rmax = get("U").shape[2];
    m.D = m.rs.length;
    m.q0 = [], m.z0 = [], m.b0 = [];
    let q = 0, z = 0, b = 0;
    for (const r of m.rs) {
      m.q0.push(q); m.z0.push(z); m.b0.push(b);
      q += r; z += 6 + r; b += r * r;
    }
    m.Q = q;
    m.Z = z;
    m.polynomials = m.rs.map((r, d) => {
      const o = m.poly_offsets.subarray(3 * d, 3 * d + 3);
      return { c0: m.c0[d], c1: m.c1.subarray(m.q0[d], m.q0[d] + r),
               C2: m.C2.subarray(o[0], o[0] + r * r), S3: m.S3.subarray(o[1], o[1] + r ** 3),
               W4: m.W4.subarray(o[2], o[2] + (r * (r + 1) * (r + 2)) / 6 * r), r };
    });
    joints(m, get("joint_tets"), get("joint_grads").shape);
    this.m = m;
    this.r = m.Z;
    this.reset();
  }

  reset() {
    this.now = rest(this.m);
    this.before = rest(this.m);
    this.x = new Float64Array(this.arrays.rest_positions.data);
    this.steps = 0;
  }

  // One step under gravity plus extra (Float64Array 3 n, N per vertex, or null), the held
  // vertices moved to base (12 numbers, [R_g | c_g] row by row; null: where they are);
  // returns the wall time in ms (the step and the positions).
  async step(extra, base) {
    const start = performance.now();
    const force = new Float64Array(this.gravity);
    if (extra) for (let i = 0; i < force.length; i++) force[i] += extra[i];
    const next = newton(this, force, base ? Float64Array.from(base) : this.now.base);
    this.before = this.now;
    this.now = next;
    positions(this.m, this.arrays.rest_positions.data, next, null, this.x);
    this.steps += 1;
    return performance.now() - start;
  }
}

function rest(m) {
  const R = new Float64Array(9 * m.D);
  for (let d = 0; d < m.D; d++) R[9 * d] = R[9 * d + 4] = R[9 * d + 8] = 1;
  return { c: new Float64Array(m.centre), R, q: new Float64Array(m.Q),
           base: Float64Array.of(1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0) };
}

// The joints: their nodes (compact numbering), each element's nodes in it, the node pairs
// that share an element (sorted, with a pointer per first node) and each element's pairs
function joints(m, tetsArray, gradShape) {
  const [count, points, k] = gradShape;
  const tets = tetsArray.data;
  const nodes = Array.from(new Set(tets)).sort((a, b) => a - b);
  const local = new Map(nodes.map((v, i) => [v, i]));
  m.jointNodes = Int32Array.from(nodes);
  m.jointTets = Int32Array.from(tets, (v) => local.get(v));
  m.jointCount = count;
  m.jointPoints = points;
  m.jointK = k;
  const keys = new Set();
  for (let e = 0; e < count; e++) {
    for (let a = 0; a < k; a++) {
      for (let b = 0; b < k; b++) {
        keys.add(m.jointTets[e * k + a] * nodes.length + m.jointTets[e * k + b]);
      }
    }
  }
  const sorted = Array.from(keys).sort((a, b) => a - b);
  const index = new Map(sorted.map((v, i) => [v, i]));
  m.pairs = Int32Array.from(sorted.flatMap((v) => [Math.floor(v / nodes.length),
                                                    v % nodes.length]));
  m.pairPtr = new Int32Array(nodes.length + 1);
  for (let p = 0; p < sorted.length; p++) m.pairPtr[m.pairs[2 * p] + 1] += 1;
  for (let i = 0; i < nodes.length; i++) m.pairPtr[i + 1] += m.pairPtr[i];
  m.elementPairs = new Int32Array(count * k * k);
  for (let e = 0; e < count; e++) {
    for (let a = 0; a < k; a++) {
      for (let b = 0; b < k; b++) {
        m.elementPairs[(e * k + a) * k + b] = index.get(
          m.jointTets[e * k + a] * nodes.length + m.jointTets[e * k + b]);
      }
    }
  }
  m.jointLabels = Int32Array.from(nodes, (v) => m.labels[v]);
}

// positions (3 per node) of `nodes` (all where null) into out
function positions(m, restPositions, s, nodes, out) {
  const count = nodes ? nodes.length : m.labels.length;
  for (let k = 0; k < count; k++) {
    const i = nodes ? nodes[k] : k;
    const d = m.labels[i];
    if (d < 0) {
      const b = s.base;
      for (let a = 0; a < 3; a++) {
        out[3 * k + a] = b[4 * a] * restPositions[3 * i] + b[4 * a + 1] * restPositions[3 * i + 1]
          + b[4 * a + 2] * restPositions[3 * i + 2] + b[4 * a + 3];
      }
      continue;
    }
    const y = [0, 0, 0];
    for (let a = 0; a < 3; a++) {
      let v = m.Y[3 * i + a];
      const row = (3 * i + a) * m.rmax;
      for (let b = 0; b < m.rs[d]; b++) v += m.U[row + b] * s.q[m.q0[d] + b];
      y[a] = v;
    }
    for (let a = 0; a < 3; a++) {
      const R = 9 * d + 3 * a;
      out[3 * k + a] = s.R[R] * y[0] + s.R[R + 1] * y[1] + s.R[R + 2] * y[2] + s.c[3 * d + a];
    }
  }
}

// the targets {T0 (9 D), T (9 Q), t (3 D)}: the force's moments plus the inertia's pull
// towards x_hat = 2 x(now) - x(before)
function targets(sim, force, inertia) {
  const { m } = sim;
  const T0 = new Float64Array(9 * m.D), T = new Float64Array(9 * m.Q);
  const t = new Float64Array(3 * m.D);
  for (let i = 0; i < m.labels.length; i++) {
    const d = m.labels[i];
    if (d < 0) continue;
    for (let a = 0; a < 3; a++) {
      const f = force[3 * i + a];
      t[3 * d + a] += f;
      for (let b = 0; b < 3; b++) {
        T0[9 * d + 3 * a + b] += f * m.Y[3 * i + b];
        const row = (3 * i + b) * m.rmax;
        for (let c = 0; c < m.rs[d]; c++) T[9 * (m.q0[d] + c) + 3 * a + b] += f * m.U[row + c];
      }
    }
  }
  const M = new Float64Array(9);
  for (const [s, alpha] of [[sim.now, 2], [sim.before, -1]]) {
    const w = inertia * alpha;
    for (let d = 0; d < m.D; d++) {
      const r = m.rs[d], q0 = m.q0[d];
      for (let k = 0; k < 9; k++) {
        let v = m.J[9 * d + k];
        for (let a = 0; a < r; a++) v += s.q[q0 + a] * m.A[9 * (q0 + a) + k];
        M[k] = v;
      }
      addProduct(w, s.R, 9 * d, M, T0, 9 * d);
      for (let b = 0; b < r; b++) {
        for (let i = 0; i < 3; i++) {
          for (let j = 0; j < 3; j++) {
            let v = m.A[9 * (q0 + b) + 3 * j + i];
            for (let a = 0; a < r; a++) {
              v += s.q[q0 + a] * m.B[9 * (m.b0[d] + a * r + b) + 3 * i + j];
            }
            M[3 * i + j] = v;
          }
        }
        addProduct(w, s.R, 9 * d, M, T, 9 * (q0 + b));
      }
      for (let i = 0; i < 3; i++) t[3 * d + i] += w * m.mass[d] * s.c[3 * d + i];
    }
  }
  return { T0, T, t };
}

// out[o..o+9] += w R[r..r+9] M
function addProduct(w, R, r, M, out, o) {
  for (let i = 0; i < 3; i++) {
    for (let j = 0; j < 3; j++) {
      out[o + 3 * i + j] += w * (R[r + 3 * i] * M[j] + R[r + 3 * i + 1] * M[3 + j]
                                 + R[r + 3 * i + 2] * M[6 + j]);
    }
  }
}

// T0_d + sum_b q_b T_b (9)
function pulled(m, d, q, T0, T) {
  const M = T0.slice(9 * d, 9 * d + 9);
  for (let b = 0; b < m.rs[d]; b++) {
    const qb = q[m.q0[d] + b];
    for (let k = 0; k < 9; k++) M[k] += qb * T[9 * (m.q0[d] + b) + k];
  }
  return M;
}

// [e_j]_x R (9) for each j
function turned(R, o) {
  const out = [];
  for (let j = 0; j < 3; j++) {
    const G = new Float64Array(9);
    for (let b = 0; b < 3; b++) {
      const r0 = R[o + b], r1 = R[o + 3 + b], r2 = R[o + 6 + b];
      if (j === 0) { G[3 + b] = -r2; G[6 + b] = r1; }
      if (j === 1) { G[b] = r2; G[6 + b] = -r0; }
      if (j === 2) { G[b] = -r1; G[3 + b] = r0; }
    }
    out.push(G);
  }
  return out;
}

// [e_i]_x M (9)
function cross(i, M) {
  const G = new Float64Array(9);
  for (let b = 0; b < 3; b++) {
    if (i === 0) { G[3 + b] = -M[6 + b]; G[6 + b] = M[3 + b]; }
    if (i === 1) { G[b] = M[6 + b]; G[6 + b] = -M[b]; }
    if (i === 2) { G[b] = -M[3 + b]; G[3 + b] = M[b]; }
  }
  return G;
}

function sum9(A, B) {
  let s = 0;
  for (let k = 0; k < 9; k++) s += A[k] * B[k];
  return s;
}

// the step's energy, and with derivatives (g, H) set (in each domain's centre, turn and q)
function energy(sim, s, tg, inertia, g, H) {
  const { m } = sim;
  let E = 0;
  for (let d = 0; d < m.D; d++) {
    const r = m.rs[d], q0 = m.q0[d], o = m.z0[d];
    let v = 0;
    for (let i = 0; i < 3; i++) v += s.c[3 * d + i] * s.c[3 * d + i];
    v *= m.mass[d];
    for (let b = 0; b < r; b++) v += 2 * m.a[q0 + b] * s.q[q0 + b] + s.q[q0 + b] ** 2;
    const M = pulled(m, d, s.q, tg.T0, tg.T);
    const Rd = s.R.subarray(9 * d, 9 * d + 9);
    E += 0.5 * inertia * v - sum9(Rd, M);
    for (let i = 0; i < 3; i++) E -= tg.t[3 * d + i] * s.c[3 * d + i];
    const qd = s.q.subarray(q0, q0 + r);
    const P = quartic(m.polynomials[d], qd, Boolean(g));
    E += P.energy;
    if (!g) continue;
    const Z = m.Z;
    const GR = turned(s.R, 9 * d);
    for (let i = 0; i < 3; i++) {
      g[o + i] = inertia * m.mass[d] * s.c[3 * d + i] - tg.t[3 * d + i];
      g[o + 3 + i] = -sum9(GR[i], M);
      H[(o + i) * Z + o + i] = inertia * m.mass[d];
      for (let k = 0; k < 3; k++) {
        const a = cross(i, GR[k]), b = cross(k, GR[i]);
        let v2 = 0;
        for (let e = 0; e < 9; e++) v2 += 0.5 * (a[e] + b[e]) * M[e];
        H[(o + 3 + i) * Z + o + 3 + k] = -v2;
      }
    }
    for (let b = 0; b < r; b++) {
      const Tb = tg.T.subarray(9 * (q0 + b), 9 * (q0 + b) + 9);
      g[o + 6 + b] = inertia * (m.a[q0 + b] + s.q[q0 + b]) - sum9(Rd, Tb) + P.gradient[b];
      H[(o + 6 + b) * Z + o + 6 + b] = inertia;
      for (let j = 0; j < 3; j++) {
        const v3 = -sum9(GR[j], Tb);
        H[(o + 3 + j) * Z + o + 6 + b] = v3;
        H[(o + 6 + b) * Z + o + 3 + j] = v3;
      }
      for (let c = 0; c < r; c++) H[(o + 6 + b) * Z + o + 6 + c] += P.hessian[b * r + c];
    }
  }
  const x = new Float64Array(3 * m.jointNodes.length);
  positions(m, sim.arrays.rest_positions.data, s, m.jointNodes, x);
  return E + jointTerms(m, s, x, g, H);
}

// the joints' energy; with g, their gradient and Hessian chained through each node's frame
function jointTerms(m, s, x, g, H) {
  const { jointCount: count, jointPoints: points, jointK: k } = m;
  const G = m.joint_grads, W = m.joint_weights;
  const nodes = m.jointNodes.length;
  const grad = g ? new Float64Array(3 * nodes) : null;
  const blocks = g ? new Float64Array(9 * (m.pairs.length / 2)) : null;
  const F = new Float64Array(9), S = new Float64Array(9), Fd = new Float64Array(3);
  const q = new Float64Array(3 * k), sd = new Float64Array(k);
  let E = 0;
  for (let e = 0; e < count; e++) {
    const mu = m.mu[e], lam = m.lam[e], kappa = m.kappa[e];
    const d = m.fiber.subarray(3 * e, 3 * e + 3);
    for (let p = 0; p < points; p++) {
      const Gp = (e * points + p) * k * 3;
      const w = W[e * points + p];
      F.fill(0);
      for (let a = 0; a < k; a++) {
        const node = m.jointTets[e * k + a];
        for (let i = 0; i < 3; i++) {
          for (let j = 0; j < 3; j++) F[3 * i + j] += x[3 * node + i] * G[Gp + 3 * a + j];
        }
      }
      let trE = 0, EE = 0;
      for (let i = 0; i < 3; i++) {
        for (let j = 0; j < 3; j++) {
          let v = 0;
          for (let l = 0; l < 3; l++) v += F[3 * l + i] * F[3 * l + j];
          S[3 * i + j] = 0.5 * (v - (i === j ? 1 : 0));
        }
      }
      for (let i = 0; i < 3; i++) trE += S[4 * i];
      for (let i = 0; i < 9; i++) EE += S[i] * S[i];
      for (let i = 0; i < 9; i++) S[i] *= 2 * mu;
      for (let i = 0; i < 3; i++) S[4 * i] += lam * trE;
      for (let i = 0; i < 3; i++) Fd[i] = F[3 * i] * d[0] + F[3 * i + 1] * d[1] + F[3 * i + 2] * d[2];
      const I4m1 = Fd[0] * Fd[0] + Fd[1] * Fd[1] + Fd[2] * Fd[2] - 1;
      for (let i = 0; i < 3; i++) {
        for (let j = 0; j < 3; j++) S[3 * i + j] += 4 * kappa * I4m1 * d[i] * d[j];
      }
      E += w * (0.5 * lam * trE * trE + mu * EE + kappa * I4m1 * I4m1);
      if (!g) continue;
      for (let a = 0; a < k; a++) {
        const node = m.jointTets[e * k + a];
        sd[a] = 0;
        for (let i = 0; i < 3; i++) {
          let qa = 0;
          for (let j = 0; j < 3; j++) qa += F[3 * i + j] * G[Gp + 3 * a + j];
          q[3 * a + i] = qa;
          sd[a] += d[i] * G[Gp + 3 * a + i];
          // P G_a = F S G_a
          let v = 0;
          for (let j = 0; j < 3; j++) {
            let SG = 0;
            for (let l = 0; l < 3; l++) SG += S[3 * j + l] * G[Gp + 3 * a + l];
            v += F[3 * i + j] * SG;
          }
          grad[3 * node + i] += w * v;
        }
      }
      for (let a = 0; a < k; a++) {
        for (let b = 0; b < k; b++) {
          let GSG = 0, GG = 0;
          for (let i = 0; i < 3; i++) {
            GG += G[Gp + 3 * a + i] * G[Gp + 3 * b + i];
            for (let j = 0; j < 3; j++) GSG += G[Gp + 3 * a + i] * S[3 * i + j] * G[Gp + 3 * b + j];
          }
          const block = 9 * m.elementPairs[(e * k + a) * k + b];
          for (let i = 0; i < 3; i++) {
            for (let l = 0; l < 3; l++) {
              let FF = 0;
              for (let j = 0; j < 3; j++) FF += F[3 * i + j] * F[3 * l + j];
              blocks[block + 3 * i + l] += w * ((i === l ? GSG : 0) + mu * q[3 * b + i] * q[3 * a + l]
                + mu * FF * GG + lam * q[3 * a + i] * q[3 * b + l]
                + 8 * kappa * Fd[i] * Fd[l] * sd[a] * sd[b]);
            }
          }
        }
      }
    }
  }
  if (g) chainJoints(m, s, x, grad, blocks, g, H);
  return E;
}

// the joints' gradient and Hessian (node gradients grad, pair blocks) in each node's domain
// unknowns: J_i = [I | -[w]_x | R U_i], w = x_i - c
function chainJoints(m, s, x, grad, blocks, g, H) {
  const nodes = m.jointNodes.length, Z = m.Z, width = 6 + m.rmax;
  const Jn = new Float64Array(nodes * 3 * width);
  for (let i = 0; i < nodes; i++) {
    const d = m.jointLabels[i];
    if (d < 0) continue;
    const w = [0, 1, 2].map((a) => x[3 * i + a] - s.c[3 * d + a]);
    const J = 3 * i * width;
    for (let a = 0; a < 3; a++) Jn[J + a * width + a] = 1;
    Jn[J + 4] = w[2]; Jn[J + 5] = -w[1];
    Jn[J + width + 3] = -w[2]; Jn[J + width + 5] = w[0];
    Jn[J + 2 * width + 3] = w[1]; Jn[J + 2 * width + 4] = -w[0];
    const node = m.jointNodes[i];
    for (let a = 0; a < 3; a++) {
      for (let b = 0; b < m.rs[d]; b++) {
        let v = 0;
        for (let c = 0; c < 3; c++) v += s.R[9 * d + 3 * a + c] * m.U[(3 * node + c) * m.rmax + b];
        Jn[J + a * width + 6 + b] = v;
      }
    }
  }
  const K = new Float64Array(3 * Z);
  const touched = new Uint8Array(m.D);
  for (let i = 0; i < nodes; i++) {
    const d = m.jointLabels[i];
    if (d < 0) continue;
    const o = m.z0[d], rd = m.rs[d];
    const gi = grad.subarray(3 * i, 3 * i + 3);
    const w = [0, 1, 2].map((a) => x[3 * i + a] - s.c[3 * d + a]);
    for (let a = 0; a < 3; a++) g[o + a] += gi[a];
    g[o + 3] += w[1] * gi[2] - w[2] * gi[1];
    g[o + 4] += w[2] * gi[0] - w[0] * gi[2];
    g[o + 5] += w[0] * gi[1] - w[1] * gi[0];
    const gw = gi[0] * w[0] + gi[1] * w[1] + gi[2] * w[2];
    for (let a = 0; a < 3; a++) {
      for (let b = 0; b < 3; b++) H[(o + 3 + a) * Z + o + 3 + b] += 0.5 * (gi[a] * w[b] + gi[b] * w[a]);
      H[(o + 3 + a) * Z + o + 3 + a] -= gw;
    }
    const J = 3 * i * width;
    for (let b = 0; b < rd; b++) {
      const v0 = Jn[J + 6 + b], v1 = Jn[J + width + 6 + b], v2 = Jn[J + 2 * width + 6 + b];
      g[o + 6 + b] += v0 * gi[0] + v1 * gi[1] + v2 * gi[2];
      const cr = [v1 * gi[2] - v2 * gi[1], v2 * gi[0] - v0 * gi[2], v0 * gi[1] - v1 * gi[0]];
      for (let a = 0; a < 3; a++) {
        H[(o + 3 + a) * Z + o + 6 + b] += cr[a];
        H[(o + 6 + b) * Z + o + 3 + a] += cr[a];
      }
    }
    touched.fill(0);
    for (let p = m.pairPtr[i]; p < m.pairPtr[i + 1]; p++) {
      const j = m.pairs[2 * p + 1], dj = m.jointLabels[j];
      if (dj < 0) continue;
      const oj = m.z0[dj], nj = 6 + m.rs[dj];
      if (!touched[dj]) {
        touched[dj] = 1;
        for (let a = 0; a < 3; a++) K.fill(0, a * Z + oj, a * Z + oj + nj);
      }
      for (let a = 0; a < 3; a++) {
        for (let b = 0; b < 3; b++) {
          const h = blocks[9 * p + 3 * a + b];
          const Jj = (3 * j + b) * width;
          for (let v = 0; v < nj; v++) K[a * Z + oj + v] += h * Jn[Jj + v];
        }
      }
    }
    for (let e = 0; e < m.D; e++) {
      if (!touched[e]) continue;
      const oe = m.z0[e], ne = 6 + m.rs[e];
      for (let u = 0; u < 6 + rd; u++) {
        const j0 = Jn[J + u], j1 = Jn[J + width + u], j2 = Jn[J + 2 * width + u];
        if (j0 === 0 && j1 === 0 && j2 === 0) continue;
        for (let v = 0; v < ne; v++) {
          H[(o + u) * Z + oe + v] += j0 * K[oe + v] + j1 * K[Z + oe + v] + j2 * K[2 * Z + oe + v];
        }
      }
    }
  }
}

// the derivatives in the tree's unknowns: {E, g, H, N (3 D, Z)}
function derivatives(sim, s, tg, inertia) {
  const { m } = sim, Z = m.Z, D = m.D;
  const g = new Float64Array(Z), H = new Float64Array(Z * Z);
  const E = energy(sim, s, tg, inertia, g, H);
  const N = new Float64Array(3 * D * Z);
  for (let p = 0; p < m.chain.length / 2; p++) {
    const f = m.chain[2 * p], d = m.chain[2 * p + 1];
    const w = [0, 1, 2].map((i) => s.R[9 * f + 3 * i] * m.arms[3 * p]
      + s.R[9 * f + 3 * i + 1] * m.arms[3 * p + 1] + s.R[9 * f + 3 * i + 2] * m.arms[3 * p + 2]);
    const zc = m.z0[f], zt = m.z0[f] + 3;
    if (f !== d) for (let a = 0; a < 3; a++) N[(3 * d + a) * Z + zc + a] += 1;
    N[(3 * d) * Z + zt + 1] += w[2];
    N[(3 * d) * Z + zt + 2] -= w[1];
    N[(3 * d + 1) * Z + zt] -= w[2];
    N[(3 * d + 1) * Z + zt + 2] += w[0];
    N[(3 * d + 2) * Z + zt] += w[1];
    N[(3 * d + 2) * Z + zt + 1] -= w[0];
    const gc = [0, 1, 2].map((a) => g[m.z0[d] + a]);
    const gw = gc[0] * w[0] + gc[1] * w[1] + gc[2] * w[2];
    for (let a = 0; a < 3; a++) {
      for (let b = 0; b < 3; b++) H[(zt + a) * Z + zt + b] += 0.5 * (gc[a] * w[b] + gc[b] * w[a]);
      H[(zt + a) * Z + zt + a] -= gw;
    }
  }
  const C = [];
  for (let d = 0; d < D; d++) for (let a = 0; a < 3; a++) C.push(m.z0[d] + a);
  // HN (Z, Z) = H[:, C] N; then H + HN + HN^T + N^T H[C, C] N
  const HN = new Float64Array(Z * Z);
  for (let i = 0; i < Z; i++) {
    for (let c = 0; c < C.length; c++) {
      const h = H[i * Z + C[c]];
      if (h === 0) continue;
      for (let j = 0; j < Z; j++) HN[i * Z + j] += h * N[c * Z + j];
    }
  }
  const CN = new Float64Array(C.length * Z);           // H[C, C] N
  for (let a = 0; a < C.length; a++) {
    for (let c = 0; c < C.length; c++) {
      const h = H[C[a] * Z + C[c]];
      if (h === 0) continue;
      for (let j = 0; j < Z; j++) CN[a * Z + j] += h * N[c * Z + j];
    }
  }
  const out = new Float64Array(Z * Z);
  for (let i = 0; i < Z; i++) {
    for (let j = 0; j < Z; j++) out[i * Z + j] = H[i * Z + j] + HN[i * Z + j] + HN[j * Z + i];
  }
  for (let a = 0; a < C.length; a++) {
    for (let i = 0; i < Z; i++) {
      const n = N[a * Z + i];
      if (n === 0) continue;
      for (let j = 0; j < Z; j++) out[i * Z + j] += n * CN[a * Z + j];
    }
  }
  const gOut = Float64Array.from(g);
  for (let a = 0; a < C.length; a++) {
    for (let i = 0; i < Z; i++) gOut[i] += N[a * Z + i] * g[C[a]];
  }
  return { E, g: gOut, H: out, N, C };
}

// Newton from the extrapolated state, the held vertices at base: the next state
function newton(sim, force, base) {
  const { m } = sim;
  const inertia = 1 / (sim.dt * sim.dt);
  const tg = targets(sim, force, inertia);
  let s = extrapolated(m, sim.now, sim.before, base);
  const tolerance = STEP_TOLERANCE * sim.size;
  let bound = Infinity;
  for (let it = 1; it <= MAX_ITER; it++) {
    const { E, g, H, N, C } = derivatives(sim, s, tg, inertia);
    if (!Number.isFinite(E) || !g.every(Number.isFinite)) {
      throw new Error(`step ${sim.steps + 1}: the framed model's energy is not finite`);
    }
    const dz = descent(H, g, m.Z);
    const last = bound;
    bound = moveBound(m, dz, N, C);
    if (bound <= tolerance || (bound < last && last < Infinity && bound * bound / last <= tolerance)) {
      return orthonormal(retract(m, s, dz, 1));
    }
    let alpha = 1;
    const slope = dot(g, dz);
    for (;;) {
      const trial = retract(m, s, dz, alpha);
      if (energy(sim, trial, tg, inertia, null, null) <= E + ARMIJO * alpha * slope) {
        s = trial;
        break;
      }
      alpha *= 0.5;
      if (alpha * bound <= tolerance) {
        if (bound <= 1e3 * tolerance) return s;
        throw new Error(`step ${sim.steps + 1}: the framed model's line search found no decrease`);
      }
    }
  }
  throw new Error(`step ${sim.steps + 1}: the framed model's Newton took ${MAX_ITER} iterations`);
}

// -H^-1 g by Cholesky, or with H's eigenvalues mirrored and floored at 1e-10 of the largest
function descent(H, g, r) {
  const L = cholesky(H, r, 0);
  if (L) return choleskySolve(L, g, r).map((v) => -v);
  const [lam, V] = jacobiEigen(H, r);
  let largest = 0;
  for (const l of lam) largest = Math.max(largest, Math.abs(l));
  const out = new Float64Array(r);
  for (let k = 0; k < r; k++) {
    let c = 0;
    for (let i = 0; i < r; i++) c += V[i * r + k] * g[i];
    c /= Math.max(Math.abs(lam[k]), 1e-10 * largest);
    for (let i = 0; i < r; i++) out[i] -= V[i * r + k] * c;
  }
  return out;
}

// eigenvalues and eigenvectors (columns) of symmetric H (r, r) by cyclic Jacobi rotations
function jacobiEigen(H, r) {
  const A = Float64Array.from(H), V = new Float64Array(r * r);
  for (let i = 0; i < r; i++) V[i * r + i] = 1;
  for (let sweep = 0; sweep < 100; sweep++) {
    let off = 0, diag = 0;
    for (let i = 0; i < r; i++) {
      diag += A[i * r + i] ** 2;
      for (let j = i + 1; j < r; j++) off += A[i * r + j] ** 2;
    }
    if (off <= 1e-30 * diag) break;
    for (let p = 0; p < r; p++) {
      for (let q = p + 1; q < r; q++) {
        const apq = A[p * r + q];
        if (apq === 0) continue;
        const theta = (A[q * r + q] - A[p * r + p]) / (2 * apq);
        const t = Math.sign(theta || 1) / (Math.abs(theta) + Math.sqrt(theta * theta + 1));
        const c = 1 / Math.sqrt(t * t + 1), s = t * c;
        for (let k = 0; k < r; k++) {
          const akp = A[k * r + p], akq = A[k * r + q];
          A[k * r + p] = c * akp - s * akq;
          A[k * r + q] = s * akp + c * akq;
        }
        for (let k = 0; k < r; k++) {
          const apk = A[p * r + k], aqk = A[q * r + k];
          A[p * r + k] = c * apk - s * aqk;
          A[q * r + k] = s * apk + c * aqk;
        }
        for (let k = 0; k < r; k++) {
          const vkp = V[k * r + p], vkq = V[k * r + q];
          V[k * r + p] = c * vkp - s * vkq;
          V[k * r + q] = s * vkp + c * vkq;
        }
      }
    }
  }
  return [Array.from({ length: r }, (_, i) => A[i * r + i]), V];
}

// the largest node move of dz (the free-centre moves dz + N dz on the centres), m
function moveBound(m, dz, N, C) {
  const Z = m.Z;
  let worst = 0;
  for (let d = 0; d < m.D; d++) {
    const o = m.z0[d];
    let c2 = 0, t2 = 0, q2 = 0;
    for (let a = 0; a < 3; a++) {
      let v = dz[o + a];
      const row = (3 * d + a) * Z;
      for (let j = 0; j < Z; j++) v += N[row + j] * dz[j];
      c2 += v * v;
      t2 += dz[o + 3 + a] ** 2;
    }
    for (let b = 0; b < m.rs[d]; b++) q2 += dz[o + 6 + b] ** 2;
    worst = Math.max(worst, Math.sqrt(c2) + Math.sqrt(t2) * m.radius[d]
                            + Math.sqrt(q2) * m.reach[d]);
  }
  return worst;
}

// exp([theta]_x) (9) by Rodrigues' formula
function rotation(t0, t1, t2) {
  const angle = Math.hypot(t0, t1, t2);
  const first = angle > 0 ? Math.sin(angle) / angle : 1;
  const half = angle > 0 ? Math.sin(0.5 * angle) / (0.5 * angle) : 1;
  const K = [0, -t2, t1, t2, 0, -t0, -t1, t0, 0];
  const out = new Float64Array(9);
  for (let i = 0; i < 3; i++) {
    for (let j = 0; j < 3; j++) {
      let KK = 0;
      for (let l = 0; l < 3; l++) KK += K[3 * i + l] * K[3 * l + j];
      out[3 * i + j] = (i === j ? 1 : 0) + first * K[3 * i + j] + 0.5 * half * half * KK;
    }
  }
  return out;
}

function mul3(A, a, B, b, out, o) {
  for (let i = 0; i < 3; i++) {
    for (let j = 0; j < 3; j++) {
      out[o + 3 * i + j] = A[a + 3 * i] * B[b + j] + A[a + 3 * i + 1] * B[b + 3 + j]
        + A[a + 3 * i + 2] * B[b + 6 + j];
    }
  }
}

// each domain's own move t (3 D), or with moves given, the centres (3 D) they make, the
// held vertices at base
function tree(m, R, c, moves, toMoves, base) {
  for (let k = 0; k < m.D; k++) {
    const e = m.order[k], p = m.parent[e];
    for (let i = 0; i < 3; i++) {
      let v = 0;
      for (let j = 0; j < 3; j++) v += R[9 * e + 3 * i + j] * m.arm_own[3 * e + j];
      if (p < 0) {
        v += base[4 * i + 3];
        for (let j = 0; j < 3; j++) v += base[4 * i + j] * m.arm_parent[3 * e + j];
      } else {
        v += c[3 * p + i];
        for (let j = 0; j < 3; j++) v += R[9 * p + 3 * i + j] * m.arm_parent[3 * e + j];
      }
      if (toMoves) moves[3 * e + i] = c[3 * e + i] - v;
      else c[3 * e + i] = v + moves[3 * e + i];
    }
  }
}

function ownMoves(m, s) {
  const t = new Float64Array(3 * m.D);
  tree(m, s.R, s.c, t, true, s.base);
  return t;
}

function retract(m, s, dz, alpha) {
  const R = new Float64Array(9 * m.D);
  const t = ownMoves(m, s);
  const q = Float64Array.from(s.q);
  for (let d = 0; d < m.D; d++) {
    const o = m.z0[d];
    const turn = rotation(alpha * dz[o + 3], alpha * dz[o + 4], alpha * dz[o + 5]);
    mul3(turn, 0, s.R, 9 * d, R, 9 * d);
    for (let a = 0; a < 3; a++) t[3 * d + a] += alpha * dz[o + a];
    for (let b = 0; b < m.rs[d]; b++) q[m.q0[d] + b] += alpha * dz[o + 6 + b];
  }
  const c = new Float64Array(3 * m.D);
  tree(m, R, c, t, false, s.base);
  return { c, R, q, base: s.base };
}

// Newton's start, the held vertices at base: each frame turned on by its last turn, its own
// move and q carried on
function extrapolated(m, now, before, base) {
  const R = new Float64Array(9 * m.D), turn = new Float64Array(9), bt = new Float64Array(9);
  for (let d = 0; d < m.D; d++) {
    for (let i = 0; i < 3; i++) for (let j = 0; j < 3; j++) bt[3 * i + j] = before.R[9 * d + 3 * j + i];
    mul3(now.R, 9 * d, bt, 0, turn, 0);
    mul3(turn, 0, now.R, 9 * d, R, 9 * d);
  }
  nearestRotations(R, m.D);
  const a = ownMoves(m, now), b = ownMoves(m, before);
  const moves = a.map((v, i) => 2 * v - b[i]);
  const c = new Float64Array(3 * m.D);
  tree(m, R, c, moves, false, base);
  return { c, R, q: now.q.map((v, i) => 2 * v - before.q[i]), base };
}

function orthonormal(s) {
  nearestRotations(s.R, s.R.length / 9);
  return s;
}

// each 3 x 3 block of R replaced by its nearest rotation (the polar factor, by Newton's
// iteration X <- (X + X^-T) / 2 to round-off)
function nearestRotations(R, D) {
  for (let d = 0; d < D; d++) {
    const X = R.subarray(9 * d, 9 * d + 9);
    for (let it = 0; it < 20; it++) {
      const [a, b, c, e, f, g, h, i, j] = X;
      const det = a * (f * j - g * i) - b * (e * j - g * h) + c * (e * i - f * h);
      const invT = [(f * j - g * i) / det, -(e * j - g * h) / det, (e * i - f * h) / det,
                    -(b * j - c * i) / det, (a * j - c * h) / det, -(a * i - b * h) / det,
                    (b * g - c * f) / det, -(a * g - c * e) / det, (a * f - b * e) / det];
      let change = 0;
      for (let k = 0; k < 9; k++) {
        const v = 0.5 * (X[k] + invT[k]);
        change = Math.max(change, Math.abs(v - X[k]));
        X[k] = v;
      }
      if (change <= 1e-16) break;
    }
  }
}
