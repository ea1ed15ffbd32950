// Step a baked scene's reduced model (python -m export bake-reduced) in plain JavaScript: the
// browser's side of export/runtime.py's ReducedSimulator (export/README.md: Reduced models).
// Positions x = rest + basis q; the energy is the quartic c1 . q + q^T C2 q / 2 + S3[q, q, q] +
// S4[q, q, q, q], W4 holding S4[a, b, c, :] for the sorted triples a <= b <= c in
// lexicographic order; a step is Newton on the backward-Euler potential in r dimensions.
import { loadScene } from "./stepper.js";

const RTOL = 1e-8;
const MAX_ITER = 50;
const ARMIJO = 1e-4;

// {header, arrays} of the reduced models at url (without extension): linear, or framed
// (framed.js).
export async function loadReduced(url) {
  const scene = await loadScene(url);
  if (!["anisofem-reduced-1", "anisofem-framed-1"].includes(scene.header.model_format)) {
    throw new Error(`reduced model: ${url}.json holds no reduced model ` +
                    `(model_format ${scene.header.model_format})`);
  }
  return scene;
}

// The reduced model of a scene at one fiber angle: the interface of stepper.js's Simulation
// (n, dt, x, steps, reset, step, setFiberAngle, fiberAngle).
export class ReducedSimulation {
  constructor(scene, fiberAngle) {
    this.header = scene.header;
    this.arrays = scene.arrays;
    this.n = this.header.n;
    this.dt = this.header.dt;
    this.gravity = new Float64Array(3 * this.n);
    for (let i = 0; i < this.n; i++) {
      for (let c = 0; c < 3; c++) {
        this.gravity[3 * i + c] = this.arrays.masses.data[i] * this.header.gravity[c];
      }
    }
    this.setFiberAngle(fiberAngle);
  }

  setFiberAngle(angle) {
    const tag = `@${angle}`;
    const a = this.arrays;
    if (!(`W4${tag}` in a)) throw new Error(`reduced model: no fiber angle ${angle}`);
    this.fiberAngle = angle;
    this.basis = a[`basis${tag}`].data;
    this.r = a[`basis${tag}`].shape[2];
    this.c1 = a[`c1${tag}`].data;
    this.C2 = a[`C2${tag}`].data;
    this.S3 = a[`S3${tag}`].data;
    this.W4 = a[`W4${tag}`].data;
    const index = this.header.fiber_angles.indexOf(angle);
    this.validation = this.header.validation[index];
    this.reset();
  }

  reset() {
    this.q = new Float64Array(this.r);
    this.w = new Float64Array(this.r);
    this.x = new Float64Array(this.arrays.rest_positions.data);
    this.steps = 0;
  }

  // One step under gravity plus extra (Float64Array 3 n, N per vertex, or null); returns the
  // wall time in ms (the step and the positions).
  async step(extra) {
    const start = performance.now();
    const { n, r, basis } = this;
    const load = new Float64Array(r);
    for (let i = 0; i < 3 * n; i++) {
      const f = this.gravity[i] + (extra ? extra[i] : 0);
      if (f === 0) continue;
      for (let a = 0; a < r; a++) load[a] += f * basis[i * r + a];
    }
    const q = newton(this, load);
    for (let a = 0; a < r; a++) this.w[a] = (q[a] - this.q[a]) / this.dt;
    this.q = q;
    const rest = this.arrays.rest_positions.data;
    for (let i = 0; i < 3 * n; i++) {
      let s = rest[i];
      for (let a = 0; a < r; a++) s += basis[i * r + a] * q[a];
      this.x[i] = s;
    }
    this.steps += 1;
    return performance.now() - start;
  }
}

// Backward Euler from (sim.q, sim.w) under the reduced load: the next q.
function newton(sim, load) {
  const { r, dt, c1, C2, S3, W4 } = sim;
  const inertia = 1 / (dt * dt);
  const qHat = new Float64Array(r);
  for (let a = 0; a < r; a++) qHat[a] = sim.q[a] + dt * sim.w[a];
  let x = Float64Array.from(qHat);
  let A = matvec(W4, x, r);
  let tolerance = RTOL * (norm(load) + norm(sim.w) / dt);
  let residual = Infinity;
  for (let it = 0; it <= MAX_ITER; it++) {
    const X = quarticMatrix(A, x, r);
    const Y = matvec(S3, x, r);               // S3[x] (r, r)
    const g = new Float64Array(r);
    const H = new Float64Array(r * r);
    for (let a = 0; a < r; a++) {
      let s = c1[a];
      for (let b = 0; b < r; b++) {
        const k = a * r + b;
        s += (C2[k] + 3 * Y[k] + 4 * X[k]) * x[b];
        H[k] = C2[k] + 6 * Y[k] + 12 * X[k];
      }
      g[a] = s;
      H[a * r + a] += inertia;
    }
    if (it === 0) tolerance += RTOL * norm(g);
    for (let a = 0; a < r; a++) g[a] += inertia * (x[a] - qHat[a]) - load[a];
    residual = norm(g);
    if (!Number.isFinite(residual)) throw new Error("step: the reduced force is not finite");
    if (residual <= Math.max(tolerance, roundoff(H, x, load, c1, r))) return x;
    if (it === MAX_ITER) break;
    const p = positiveSolve(H, g, r);
    for (let a = 0; a < r; a++) p[a] = -p[a];
    const a1 = dot(g, p);
    if (!(a1 < 0)) break;
    const a2 = 0.5 * dot(p, matvec(H, p, r));
    const Ap = matvec(W4, p, r);
    const Yp = matvec(S3, p, r);
    const [mixed, pure] = cubicForms(A, Ap, p, r);
    const a3 = dot(p, matvec(Yp, p, r)) + 4 * mixed;
    let t = 1;
    while (t * (a2 + t * (a3 + t * pure)) > -(1 - ARMIJO) * a1 && t >= 1e-12) t *= 0.5;
    if (t < 1e-12) break;
    x = x.map((v, a) => v + t * p[a]);
    A = A.map((v, k) => v + t * Ap[k]);
  }
  throw new Error(`step ${sim.steps + 1}: the reduced Newton stopped at a gradient of ` +
                  `${residual.toExponential(3)}`);
}

// M x for M (rows, r) row-major
function matvec(M, x, r) {
  const rows = M.length / r;
  const out = new Float64Array(rows);
  for (let i = 0; i < rows; i++) {
    let s = 0;
    for (let j = 0; j < r; j++) s += M[i * r + j] * x[j];
    out[i] = s;
  }
  return out;
}

// The quartic c0 + c1.q + q C2 q / 2 + S3[q, q, q] + S4[q, q, q, q] of P {c0, c1, C2, S3, W4,
// r}: {energy}, with derivatives also {gradient (r), hessian (r, r)}
export function quartic(P, q, derivatives) {
  const { r, c0, c1, C2, S3, W4 } = P;
  const X = quarticMatrix(matvec(W4, q, r), q, r);
  const Y = matvec(S3, q, r);
  const gradient = derivatives ? new Float64Array(r) : null;
  const hessian = derivatives ? new Float64Array(r * r) : null;
  let energy = c0;
  for (let a = 0; a < r; a++) {
    let Cq = 0, Yq = 0, Xq = 0;
    for (let b = 0; b < r; b++) {
      const k = a * r + b;
      Cq += C2[k] * q[b];
      Yq += Y[k] * q[b];
      Xq += X[k] * q[b];
      if (derivatives) hessian[k] = C2[k] + 6 * Y[k] + 12 * X[k];
    }
    energy += q[a] * (c1[a] + 0.5 * Cq + Yq + Xq);
    if (derivatives) gradient[a] = c1[a] + Cq + 3 * Yq + 4 * Xq;
  }
  return { energy, gradient, hessian };
}

// X = S4[x, x] (r, r) from A = W4 x: each sorted triple adds to (a, b) with x_c, to (a, c)
// with x_b where b != c, to (b, c) with x_a where a != b; then the lower triangle is mirrored
function quarticMatrix(A, x, r) {
  const X = new Float64Array(r * r);
  let t = 0;
  for (let a = 0; a < r; a++) {
    for (let b = a; b < r; b++) {
      for (let c = b; c < r; c++) {
        const v = A[t++];
        X[a * r + b] += v * x[c];
        if (b !== c) X[a * r + c] += v * x[b];
        if (a !== b) X[b * r + c] += v * x[a];
      }
    }
  }
  for (let i = 0; i < r; i++) for (let j = 0; j < i; j++) X[i * r + j] = X[j * r + i];
  return X;
}

// [S4[x, p, p, p], S4[p, p, p, p]] from A = W4 x and Ap = W4 p
function cubicForms(A, Ap, p, r) {
  let mixed = 0, pure = 0, t = 0;
  for (let a = 0; a < r; a++) {
    for (let b = a; b < r; b++) {
      for (let c = b; c < r; c++) {
        const orderings = a === c ? 1 : (a === b || b === c ? 3 : 6);
        const w = orderings * p[a] * p[b] * p[c];
        mixed += w * A[t];
        pure += w * Ap[t];
        t++;
      }
    }
  }
  return [mixed, pure];
}

// the gradient norm float64 cannot resolve: eps r |(|H| |x| + |load| + |c1|)|
function roundoff(H, x, load, c1, r) {
  let s = 0;
  for (let a = 0; a < r; a++) {
    let term = Math.abs(load[a]) + Math.abs(c1[a]);
    for (let b = 0; b < r; b++) term += Math.abs(H[a * r + b]) * Math.abs(x[b]);
    s += term * term;
  }
  return Number.EPSILON * r * Math.sqrt(s);
}

// H^-1 g by Cholesky; where H is not positive definite, with H + s I for the smallest s =
// 1e-8 |H| 10^k that is (the page's stand-in for the runtime's eigenvalue clamp)
function positiveSolve(H, g, r) {
  let shift = 0;
  const scale = Math.sqrt(dot(H, H));
  for (;;) {
    const L = cholesky(H, r, shift);
    if (L) return choleskySolve(L, g, r);
    shift = shift === 0 ? 1e-8 * scale : 10 * shift;
  }
}

export function cholesky(H, r, shift) {
  const L = new Float64Array(r * r);
  for (let j = 0; j < r; j++) {
    let s = H[j * r + j] + shift;
    for (let k = 0; k < j; k++) s -= L[j * r + k] * L[j * r + k];
    if (!(s > 0)) return null;
    const d = Math.sqrt(s);
    L[j * r + j] = d;
    for (let i = j + 1; i < r; i++) {
      let v = H[i * r + j];
      for (let k = 0; k < j; k++) v -= L[i * r + k] * L[j * r + k];
      L[i * r + j] = v / d;
    }
  }
  return L;
}

export function choleskySolve(L, g, r) {
  const y = new Float64Array(r);
  for (let i = 0; i < r; i++) {
    let s = g[i];
    for (let k = 0; k < i; k++) s -= L[i * r + k] * y[k];
    y[i] = s / L[i * r + i];
  }
  const x = new Float64Array(r);
  for (let i = r - 1; i >= 0; i--) {
    let s = y[i];
    for (let k = i + 1; k < r; k++) s -= L[k * r + i] * x[k];
    x[i] = s / L[i * r + i];
  }
  return x;
}

export function dot(a, b) {
  let s = 0;
  for (let i = 0; i < a.length; i++) s += a[i] * b[i];
  return s;
}

function norm(a) {
  return Math.sqrt(dot(a, a));
}
