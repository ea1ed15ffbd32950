// Step an exported anisognn model (export/models/*.onnx) on a baked scene (python -m export
// bake) with onnxruntime-web: the browser's side of export/runtime.py's OnnxSimulator.
import * as ort from "onnxruntime-web";

const ARRAYS = { float64: Float64Array, float32: Float32Array, int64: BigInt64Array,
                 int32: Int32Array, uint8: Uint8Array };
const STATE = ["positions", "velocities", "external_force"];
// the inputs that depend on the fiber, baked once per angle as NAME@ANGLE
const FIBER_INPUTS = ["fiber", "tet_fiber"];

// {header, arrays: {name: {data, dtype, shape}}, text, buffer} of a baked scene (or a reduced
// model's file) at url (without extension): the header parsed and as text, the .bin's bytes.
export async function loadScene(url) {
  const response = await fetch(`${url}.json`);
  if (!response.ok) throw new Error(`scene: ${url}.json not found (${response.status}); ` +
                                    "run `make web` to bake the scenes");
  const text = await response.text();
  const header = JSON.parse(text);
  if (header.format !== "anisognn-arrays-1") {
    throw new Error(`scene: ${url}.json is not a baked scene (format ${header.format})`);
  }
  const base = url.slice(0, url.lastIndexOf("/") + 1);
  const binary = await fetch(base + header.bin);
  if (!binary.ok) throw new Error(`scene: ${base + header.bin} not found`);
  const buffer = await binary.arrayBuffer();
  const arrays = {};
  for (const [name, spec] of Object.entries(header.arrays)) {
    const count = spec.shape.reduce((a, b) => a * b, 1);
    arrays[name] = { data: new ARRAYS[spec.dtype](buffer, spec.offset, count),
                     dtype: spec.dtype, shape: spec.shape };
  }
  return { header, arrays, text, buffer, url };
}

// A model session; a file onnxruntime cannot read, or one that is not an anisognn step
// model, is an Error with a readable message.
export async function loadModel(url) {
  ort.env.wasm.numThreads = 1;
  ort.env.wasm.wasmPaths = new URL("./node_modules/onnxruntime-web/dist/", import.meta.url).href;
  const response = await fetch(url);
  if (!response.ok) throw new Error(`model: ${url} not found (${response.status})`);
  const bytes = new Uint8Array(await response.arrayBuffer());
  let session;
  try {
    session = await ort.InferenceSession.create(bytes, { executionProviders: ["wasm"] });
  } catch (err) {
    throw new Error(`model: onnxruntime-web cannot load ${url}: ${String(err.message || err)}`);
  }
  for (const name of STATE) {
    if (!session.inputNames.includes(name)) {
      throw new Error(`model: ${url} is not an anisognn step model (no input ${name})`);
    }
  }
  return session;
}

// The simulation of a baked scene: state in float64, one backward-Euler step per call.
export class Simulation {
  constructor(session, scene, fiberAngle) {
    const { header, arrays } = scene;
    this.session = session;
    this.header = header;
    this.arrays = arrays;
    this.n = header.n;
    this.dt = header.dt;
    this.feeds = {};
    for (const name of session.inputNames) {
      if (STATE.includes(name) || FIBER_INPUTS.includes(name)) continue;
      if (!(name in arrays)) {
        throw new Error(`scene: ${header.scene} has no input ${name} that the model reads`);
      }
      this.feeds[name] = tensor(arrays[name]);
    }
    this.setFiberAngle(fiberAngle);
    this.gravity = new Float64Array(3 * this.n);
    for (let i = 0; i < this.n; i++) {
      for (let c = 0; c < 3; c++) {
        this.gravity[3 * i + c] = arrays.masses.data[i] * header.gravity[c];
      }
    }
    this.reset();
  }

  setFiberAngle(angle) {
    const tag = `@${angle}`;
    if (!(`fiber${tag}` in this.arrays)) throw new Error(`scene: no fiber angle ${angle}`);
    this.fiberAngle = angle;
    for (const name of FIBER_INPUTS) {
      if (this.session.inputNames.includes(name)) {
        this.feeds[name] = tensor(this.arrays[name + tag]);
      }
    }
  }

  reset() {
    this.x = new Float64Array(this.arrays.rest_positions.data);
    this.v = new Float64Array(3 * this.n);
    this.steps = 0;
  }

  // One step under gravity plus extra (Float64Array 3 n, N per vertex, or null); returns the
  // wall time in ms.
  async step(extra) {
    const force = new Float64Array(this.gravity);
    if (extra) for (let i = 0; i < force.length; i++) force[i] += extra[i];
    const feeds = { ...this.feeds,
      positions: new ort.Tensor("float64", this.x, [this.n, 3]),
      velocities: new ort.Tensor("float64", this.v, [this.n, 3]),
      external_force: new ort.Tensor("float64", force, [this.n, 3]) };
    const start = performance.now();
    let out;
    try {
      out = await this.session.run(feeds, ["next_positions", "next_velocities"]);
    } catch (err) {
      throw new Error(`step: the model cannot step ${this.header.title} ` +
                      `(${this.n} vertices): ${String(err.message || err)}`);
    }
    const elapsed = performance.now() - start;
    const x = out.next_positions.data, v = out.next_velocities.data;
    for (let i = 0; i < x.length; i++) {
      if (!Number.isFinite(x[i]) || !Number.isFinite(v[i])) {
        throw new Error(`step ${this.steps + 1}: the model predicted a non-finite state`);
      }
    }
    this.x = x;
    this.v = v;
    this.steps += 1;
    return elapsed;
  }
}

function tensor(array) {
  return new ort.Tensor(array.dtype, array.data, array.shape);
}
