// The page's reduced and framed models, stepped by the C runtime (export/c) built to
// WebAssembly (`make web` writes web/anisofem.wasm): this file only moves bytes in and out of
// the module. The step is the one engines link and Python calls (export/README.md).
const ERROR_SIZE = 512;
const encoder = new TextEncoder();
const decoder = new TextDecoder();
let runtime = null;

// The WebAssembly module's exports, instantiated once (it imports nothing).
async function module(url) {
  if (!runtime) {
    const response = await fetch(url);
    if (!response.ok) {
      throw new Error(`runtime: ${url} not found (${response.status}); ` +
                      "run `make web` to build it");
    }
    const { instance } = await WebAssembly.instantiate(await response.arrayBuffer(), {});
    instance.exports._initialize();
    runtime = instance.exports;
  }
  return runtime;
}

function cString(ptr) {
  const bytes = new Uint8Array(runtime.memory.buffer, ptr);
  return decoder.decode(bytes.subarray(0, bytes.indexOf(0)));
}

// bytes (Uint8Array) copied into the module's memory: its address (free it with runtime.free)
function copyIn(bytes) {
  const ptr = runtime.malloc(bytes.length + 1);
  if (!ptr) throw new Error("runtime: out of memory");
  const memory = new Uint8Array(runtime.memory.buffer);
  memory.set(bytes, ptr);
  memory[ptr + bytes.length] = 0;
  return ptr;
}

function doubles(ptr, count) { return new Float64Array(runtime.memory.buffer, ptr, count); }

// A model file's model at one fiber angle in the C runtime, with the interface the page steps
// (n, dt, x, steps, reset, step, setFiberAngle, fiberAngle, validation, framed, r, domains,
// controls, controlValues, setControls).
// scene: {header, text, buffer, url} as stepper.js's loadScene returns them.
export class ModelSimulation {
  static async create(scene, fiberAngle, url = "anisofem.wasm") {
    await module(url);
    return new ModelSimulation(scene, fiberAngle);
  }

  constructor(scene, fiberAngle) {
    this.header = scene.header;
    this.scene = scene;
    this.n = this.header.n;
    this.dt = this.header.dt;
    this.framed = this.header.model_format === "anisofem-framed-1";
    this.domains = this.header.domains;
    this.model = 0;
    this.setFiberAngle(fiberAngle);
  }

  // the file's model at fiber angle `angle` (a file of one model, without fiber_angles: null)
  setFiberAngle(angle) {
    const angles = this.header.fiber_angles;
    const index = angles ? angles.indexOf(angle) : 0;
    if (index < 0) throw new Error(`reduced model: no fiber angle ${angle}`);
    this.free();
    const header = encoder.encode(this.scene.text);
    const text = copyIn(header);
    const bin = copyIn(new Uint8Array(this.scene.buffer));
    const tag = angles ? copyIn(encoder.encode(String(angle))) : 0;
    const error = runtime.malloc(ERROR_SIZE);
    this.model = runtime.af_load_memory(text, header.length, bin, this.scene.buffer.byteLength,
                                        tag, error, ERROR_SIZE);
    const message = this.model ? ""
      : cString(error).replace(/^the header/, `${this.scene.url}.json`);
    for (const ptr of [text, bin, tag, error]) if (ptr) runtime.free(ptr);
    if (!this.model) throw new Error(`reduced model: ${message}`);
    this.fiberAngle = angles ? angle : null;
    this.validation = angles ? this.header.validation[index] : this.header.validation;
    this.size = runtime.af_state_size(this.model);
    this.r = this.framed ? (angles ? this.header.r[index] : this.header.r) : this.size / 2;
    const count = runtime.af_controls(this.model);
    this.controls = Array.from({ length: count }, (_, i) =>
      cString(runtime.af_control_name(this.model, i)));
    // the obstacles: the header's entries (kind, name, geometry), in the model's order
    this.obstacles = (this.header.contact || { obstacles: [] }).obstacles;
    this.moved = false;
    this.buffers = { state: runtime.malloc(8 * this.size), force: runtime.malloc(24 * this.n),
                     base: runtime.malloc(96), x: runtime.malloc(24 * this.n),
                     controls: runtime.malloc(8 * Math.max(count, 1)),
                     point: runtime.malloc(24) };
    const masses = doubles(runtime.af_masses(this.model), this.n);
    const gravity = doubles(this.buffers.force, 3 * this.n);
    for (let i = 0; i < 3 * this.n; i++) {
      gravity[i] = masses[Math.floor(i / 3)] * this.header.gravity[i % 3];
    }
    this.check(runtime.af_set_constant_force(this.model, this.buffers.force), "gravity");
    this.x = new Float64Array(3 * this.n);
    this.reset();
  }

  // the controls' values now (one per name in this.controls)
  controlValues() {
    return this.controls.map((_, i) => runtime.af_control_value(this.model, i));
  }

  // set the controls (one value per name in this.controls) for every later step
  setControls(values) {
    doubles(this.buffers.controls, values.length).set(values);
    this.check(runtime.af_set_controls(this.model, this.buffers.controls), "controls");
  }

  // where obstacle i is now: [x, y, z] (a plane's point, a sphere's or box's center, a
  // capsule's end a), m
  obstaclePosition(i) {
    this.check(runtime.af_obstacle_position(this.model, i, this.buffers.point), "obstacle");
    return Array.from(doubles(this.buffers.point, 3));
  }

  // obstacle i to be at position [x, y, z]: the next step moves it there as far as the body
  // lets it
  moveObstacle(i, position) {
    doubles(this.buffers.point, 3).set(position);
    this.check(runtime.af_move_obstacle(this.model, i, this.buffers.point), "obstacle");
    this.moved = true;
  }

  check(code, what) {
    if (code !== 0) throw new Error(`${what}: ${cString(runtime.af_error(this.model))}`);
  }

  free() {
    if (!this.model) return;
    runtime.af_free(this.model);
    for (const ptr of Object.values(this.buffers)) runtime.free(ptr);
    this.model = 0;
  }

  // the rest state, and the obstacles where the file has them (the model loaded again)
  reset() {
    if (this.moved) {
      this.setFiberAngle(this.fiberAngle);
      return;
    }
    runtime.af_rest_state(this.model, this.buffers.state);
    this.x.set(doubles(runtime.af_rest_positions(this.model), 3 * this.n));
    this.steps = 0;
  }

  // One step under gravity plus extra (Float64Array 3 n, N per vertex, or null), the held
  // vertices moved to base (12 numbers, [R_g | c_g] row by row; null: where they are; framed
  // models only); returns the wall time in ms (the step and the positions).
  async step(extra, base) {
    const start = performance.now();
    const { state, force, x } = this.buffers;
    if (extra) doubles(force, 3 * this.n).set(extra);
    if (base) {  // [R_g | c_g] row by row -> the C runtime's R_g (row-major), then c_g
      doubles(this.buffers.base, 12).set([base[0], base[1], base[2], base[4], base[5], base[6],
                                          base[8], base[9], base[10], base[3], base[7], base[11]]);
    }
    this.check(runtime.af_step(this.model, state, extra ? force : 0, base ? this.buffers.base : 0,
                               this.dt), `step ${this.steps + 1}`);
    runtime.af_positions(this.model, state, x);
    this.x.set(doubles(x, 3 * this.n));
    this.steps += 1;
    return performance.now() - start;
  }
}
