// The page: a baked scene stepped in real time by model.onnx or by the scene's reduced model,
// drawn with three.js, with a force applied by dragging and, for a model with controls (the
// tentacle's four bands of fibers), a slider per control; a model's obstacles (the tentacle's
// floor and ball) are drawn, and a ball, box or capsule is dragged to push the body. URL parameters: scene (cantilever,
// cylinder, t, y, tentacle), stepper (network or reduced), model (the .onnx file, default
// models/directional.onnx), angle (fiber angle, degrees), paused (1: start paused; the
// end-to-end test steps it through window.anisognn).
import * as THREE from "three";
import { OrbitControls } from "three/addons/controls/OrbitControls.js";
import { ModelSimulation } from "./runtime.js";
import { loadModel, loadScene, Simulation } from "./stepper.js";

const params = new URLSearchParams(location.search);
const ui = { scene: el("scene"), stepper: el("stepper"), angle: el("angle"), angleValue: el("angle-value"),
             carry: el("carry"), pause: el("pause"), reset: el("reset"), stats: el("stats"),
             message: el("message"), scaleHigh: el("scale-high"), controls: el("controls") };
// scenes with a reduced model only (no baked scene for the network)
const REDUCED_ONLY = ["tentacle"];
// spring constant of a drag, N/m per kg of the dragged vertices' mass (a 1 cm pull accelerates
// them at about 5 g)
const DRAG_STIFFNESS = 5000.0;
// vertices within this rest distance (m) of the picked one share the pull
const DRAG_RADIUS = 0.008;
// the carried held end of a framed model: turned about the vertical through the held
// vertices' centroid by CARRY_TURN sin(2 pi t / CARRY_PERIOD) (rad, s)
const CARRY_TURN = 0.5;
const CARRY_PERIOD = 2.0;

const renderer = new THREE.WebGLRenderer({ canvas: el("view"), antialias: true,
                                           preserveDrawingBuffer: true });
const camera = new THREE.PerspectiveCamera(40, 1, 0.001, 10);
const controls = new OrbitControls(camera, renderer.domElement);
const world = new THREE.Scene();
world.background = new THREE.Color(0xf4f4f2);
world.add(new THREE.HemisphereLight(0xffffff, 0x8899aa, 1.6));
const sun = new THREE.DirectionalLight(0xffffff, 1.8);
sun.position.set(0.3, -0.5, 0.8);
world.add(sun);

const state = { sim: null, session: null, sceneData: null, body: null, ghost: null,
                obstacles: [], held: null,
                paused: params.get("paused") === "1", drag: null, times: [], busy: false,
                lastFrame: null, owed: 0, carry: false, name: null };

function el(id) { return document.getElementById(id); }

function say(text) { ui.message.textContent = text; }

async function start() {
  ui.scene.value = params.get("scene") || "cantilever";
  ui.stepper.value = params.get("stepper") || "network";
  try {
    await openScene(ui.scene.value, params.get("angle"));
  } catch (err) {
    say(String(err.message || err));
    window.anisognn.error = String(err.message || err);
    return;
  }
  window.anisognn.ready = true;
}

// the scene `name` with the chosen stepper: the network (model.onnx, loaded once) on the baked
// scene, or the scene's reduced models (scenes/NAME-reduced, one per fiber angle)
async function openScene(name, angle) {
  if (REDUCED_ONLY.includes(name)) ui.stepper.value = "reduced";
  const reduced = ui.stepper.value === "reduced";
  if (!reduced && !state.session) {
    state.session = await loadModel(params.get("model") || "models/directional.onnx");
  }
  state.sceneData = await loadScene(`scenes/${name}${reduced ? "-reduced" : ""}`);
  const angles = state.sceneData.header.fiber_angles || [null];
  ui.angle.max = String(angles.length - 1);
  ui.angle.disabled = angles.length < 2;
  const wanted = angle === null || angle === undefined ? 45 : Number(angle);
  const index = Math.max(0, angles.findIndex((a) => a === wanted));
  ui.angle.value = String(index);
  ui.angleValue.textContent = angles[index] === null ? "-" : String(angles[index]);
  if (state.sim && state.sim.free) state.sim.free();
  state.sim = null;
  state.sim = reduced ? await ModelSimulation.create(state.sceneData, angles[index])
                      : new Simulation(state.session, state.sceneData, angles[index]);
  state.name = name;
  state.times = [];
  ui.carry.disabled = !state.sim.framed;
  buildControls();
  buildMeshes();
  buildObstacles();
  say("");
}

// a slider per control of the model (none for the others), over the range its file declares
function buildControls() {
  ui.controls.replaceChildren();
  const names = state.sim.controls || [];
  const ranges = (state.sceneData.header.loads || {}).controls || {};
  const values = names.length ? state.sim.controlValues() : [];
  names.forEach((name, i) => {
    const [low, high] = ranges[name] || [0, 1];
    const label = document.createElement("label");
    const shown = document.createElement("span");
    const input = document.createElement("input");
    Object.assign(input, { type: "range", min: String(low), max: String(high),
                           step: String((high - low) / 100), value: String(values[i]) });
    input.dataset.control = name;
    shown.textContent = values[i].toFixed(3);
    input.addEventListener("input", () => {
      shown.textContent = Number(input.value).toFixed(3);
      state.sim.setControls(Array.from(ui.controls.querySelectorAll("input"),
                                       (x) => Number(x.value)));
    });
    label.append(`${name}: `, shown, input);
    ui.controls.append(label);
  });
}

// the base ([R_g | c_g], 12 numbers row by row) of the carried held end at time t (s)
function carryBase(t) {
  const rest = state.sceneData.arrays.rest_positions.data;
  const held = state.sceneData.arrays.held.data;
  const h = [0, 0, 0];
  let count = 0;
  for (let j = 0; j < state.sim.n; j++) {
    if (!held[3 * j]) continue;
    for (let c = 0; c < 3; c++) h[c] += rest[3 * j + c];
    count += 1;
  }
  for (let c = 0; c < 3; c++) h[c] /= count;
  const a = CARRY_TURN * Math.sin((2 * Math.PI * t) / CARRY_PERIOD);
  const cos = Math.cos(a), sin = Math.sin(a);
  return [cos, -sin, 0, h[0] - (cos * h[0] - sin * h[1]),
          sin, cos, 0, h[1] - (sin * h[0] + cos * h[1]),
          0, 0, 1, 0];
}

function buildMeshes() {
  for (const mesh of [state.body, state.ghost]) if (mesh) world.remove(mesh);
  const { arrays } = state.sceneData;
  const n = state.sim.n;
  const index = new THREE.BufferAttribute(new Uint32Array(arrays.surface.data), 1);
  const rest = new Float32Array(arrays.rest_positions.data);
  const geometry = new THREE.BufferGeometry();
  geometry.setIndex(index);
  geometry.setAttribute("position", new THREE.BufferAttribute(new Float32Array(rest), 3));
  geometry.setAttribute("color", new THREE.BufferAttribute(new Float32Array(3 * n), 3));
  state.body = new THREE.Mesh(geometry, new THREE.MeshStandardMaterial(
    { vertexColors: true, roughness: 0.6, side: THREE.DoubleSide }));
  const ghostGeometry = new THREE.BufferGeometry();
  ghostGeometry.setIndex(index);
  ghostGeometry.setAttribute("position", new THREE.BufferAttribute(rest, 3));
  state.ghost = new THREE.Mesh(ghostGeometry, new THREE.MeshBasicMaterial(
    { color: 0x556677, wireframe: true, transparent: true, opacity: 0.25 }));
  world.add(state.body, state.ghost);
  ghostGeometry.computeBoundingSphere();
  const { center, radius } = ghostGeometry.boundingSphere;
  controls.target.copy(center);
  camera.up.set(0, 0, 1);
  camera.position.set(center.x + 0.4 * radius, center.y - 3.2 * radius, center.z + 1.2 * radius);
  controls.update();
  updateBody();
}

// a mesh for each of the model's obstacles (none for the network's scenes): a plane as a
// square 1 m across, a sphere, a box, a capsule
function buildObstacles() {
  for (const mesh of state.obstacles) world.remove(mesh);
  state.obstacles = [];
  const listed = state.sim.obstacles || [];
  listed.forEach((o, i) => {
    const material = new THREE.MeshStandardMaterial(
      { color: o.kind === "plane" ? 0xd8d4cc : 0xc8643c, roughness: 0.8,
        side: THREE.DoubleSide, transparent: o.kind === "plane", opacity: 0.85 });
    let geometry;
    if (o.kind === "plane") geometry = new THREE.PlaneGeometry(1, 1);
    else if (o.kind === "sphere") geometry = new THREE.SphereGeometry(o.radius, 32, 16);
    else if (o.kind === "box") geometry = new THREE.BoxGeometry(...o.half.map((h) => 2 * h));
    else {
      const axis = new THREE.Vector3(...o.b).sub(new THREE.Vector3(...o.a));
      geometry = new THREE.CapsuleGeometry(o.radius, axis.length(), 8, 16);
    }
    const mesh = new THREE.Mesh(geometry, material);
    if (o.kind === "plane") {
      mesh.quaternion.setFromUnitVectors(new THREE.Vector3(0, 0, 1),
                                         new THREE.Vector3(...o.normal));
    } else if (o.kind === "box") {
      const R = o.rotation;
      mesh.quaternion.setFromRotationMatrix(new THREE.Matrix4().set(
        R[0], R[1], R[2], 0, R[3], R[4], R[5], 0, R[6], R[7], R[8], 0, 0, 0, 0, 1));
    } else if (o.kind === "capsule") {
      const axis = new THREE.Vector3(...o.b).sub(new THREE.Vector3(...o.a)).normalize();
      mesh.quaternion.setFromUnitVectors(new THREE.Vector3(0, 1, 0), axis);
    }
    mesh.userData = { index: i, kind: o.kind, half: o.kind === "capsule" ?
      new THREE.Vector3(...o.b).sub(new THREE.Vector3(...o.a)).multiplyScalar(0.5) : null };
    state.obstacles.push(mesh);
    world.add(mesh);
  });
  updateObstacles();
}

// the obstacles' meshes where the model has them now
function updateObstacles() {
  for (const mesh of state.obstacles) {
    const at = new THREE.Vector3(...state.sim.obstaclePosition(mesh.userData.index));
    if (mesh.userData.half) at.add(mesh.userData.half);     // a capsule: from end a to its middle
    mesh.position.copy(at);
  }
}

// positions and displacement colors of the drawn body from the simulation's state
function updateBody() {
  const { x } = state.sim;
  const rest = state.sceneData.arrays.rest_positions.data;
  const position = state.body.geometry.attributes.position;
  const color = state.body.geometry.attributes.color;
  const moved = new Float64Array(state.sim.n);
  let largest = 1e-6;
  for (let i = 0; i < state.sim.n; i++) {
    moved[i] = Math.hypot(x[3 * i] - rest[3 * i], x[3 * i + 1] - rest[3 * i + 1],
                          x[3 * i + 2] - rest[3 * i + 2]);
    largest = Math.max(largest, moved[i]);
  }
  for (let i = 0; i < state.sim.n; i++) {
    const d = moved[i] / largest;
    position.setXYZ(i, x[3 * i], x[3 * i + 1], x[3 * i + 2]);
    color.setXYZ(i, 0.15 + 0.8 * d, 0.35 + 0.3 * (1 - Math.abs(2 * d - 1)), 0.85 - 0.7 * d);
  }
  ui.scaleHigh.textContent = (1e3 * largest).toPrecision(2);
  if (state.obstacles.length) updateObstacles();
  position.needsUpdate = true;
  color.needsUpdate = true;
  state.body.geometry.computeVertexNormals();
  state.body.geometry.computeBoundingSphere();
}

// the drag's external force (N per vertex component), or null
function dragForce() {
  const drag = state.drag;
  if (!drag || !drag.target) return null;
  const { x } = state.sim;
  const masses = state.sceneData.arrays.masses.data;
  const force = new Float64Array(3 * state.sim.n);
  const i = drag.vertex;
  for (const j of drag.group) {
    for (let c = 0; c < 3; c++) {
      force[3 * j + c] = DRAG_STIFFNESS * masses[j] * (drag.target.getComponent(c) - x[3 * i + c]);
    }
  }
  return force;
}

async function advance(steps) {
  for (let k = 0; k < steps; k++) {
    const carried = state.carry && state.sim.framed;
    const base = carried ? carryBase((state.sim.steps + 1) * state.sim.dt) : null;
    const ms = await state.sim.step(dragForce(), base);
    state.times.push(ms);
    if (state.times.length > 100) state.times.shift();
  }
}

function msPerStep() {
  if (!state.times.length) return NaN;
  return state.times.reduce((a, b) => a + b, 0) / state.times.length;
}

async function frame(now) {
  requestAnimationFrame(frame);
  if (state.sim && !state.paused && !state.busy) {
    state.busy = true;
    try {
      const elapsed = state.lastFrame === null ? 0 : (now - state.lastFrame) / 1000;
      state.owed = Math.min(state.owed + elapsed, 3 * state.sim.dt);
      const steps = Math.max(1, Math.floor(state.owed / state.sim.dt));
      state.owed = Math.max(0, state.owed - steps * state.sim.dt);
      await advance(steps);
      updateBody();
    } catch (err) {
      state.paused = true;
      say(String(err.message || err));
    }
    state.busy = false;
  }
  state.lastFrame = now;
  if (state.sim) {
    const ms = msPerStep();
    const speed = (1000 * state.sim.dt) / ms;
    const pace = speed >= 1 ? "real time" : `${speed.toFixed(2)}x real time`;
    const v = state.sim.validation;
    const checked = v && v.cases ? `on ${v.cases} unseen drags` : "in the static answer";
    const kind = state.sim.framed
      ? `framed reduced model, ${state.sim.domains} domains,` : "reduced model,";
    const model = v ? `${kind} r = ${state.sim.r}; its tip within ` +
      `${(100 * v.tip_error).toPrecision(2)}% of the FEM's ${checked}. ` : "";
    ui.stats.textContent = `${model}${state.sim.steps} steps of ${state.sim.dt} s, ` +
      `${ms.toFixed(2)} ms per step (${pace})`;
  }
  resize();
  renderer.render(world, camera);
}

function resize() {
  const canvas = renderer.domElement;
  const width = canvas.clientWidth, height = canvas.clientHeight;
  if (canvas.width !== width || canvas.height !== height) {
    renderer.setSize(width, height, false);
    camera.aspect = width / height;
    camera.updateProjectionMatrix();
  }
}

// dragging: the nearest surface vertex under the pointer pulls towards the pointer, on the
// plane through it facing the camera
const raycaster = new THREE.Raycaster();
function pointer(event) {
  const rect = renderer.domElement.getBoundingClientRect();
  return new THREE.Vector2(((event.clientX - rect.left) / rect.width) * 2 - 1,
                           -((event.clientY - rect.top) / rect.height) * 2 + 1);
}
renderer.domElement.addEventListener("pointerdown", (event) => {
  if (!state.sim) return;
  raycaster.setFromCamera(pointer(event), camera);
  const movable = state.obstacles.filter((mesh) => mesh.userData.kind !== "plane");
  const grabbed = raycaster.intersectObjects(movable)[0];
  if (grabbed) {   // an obstacle: it follows the pointer on the plane through it facing the camera
    const i = grabbed.object.userData.index;
    const normal = camera.getWorldDirection(new THREE.Vector3());
    state.held = { index: i, plane: new THREE.Plane().setFromNormalAndCoplanarPoint(
                     normal, grabbed.point),
                   offset: new THREE.Vector3(...state.sim.obstaclePosition(i)).sub(grabbed.point) };
    controls.enabled = false;
    return;
  }
  const hit = raycaster.intersectObject(state.body)[0];
  if (!hit) return;
  const face = [hit.face.a, hit.face.b, hit.face.c];
  const position = state.body.geometry.attributes.position;
  const vertex = face.reduce((best, j) => (
    new THREE.Vector3().fromBufferAttribute(position, j).distanceTo(hit.point) <
    new THREE.Vector3().fromBufferAttribute(position, best).distanceTo(hit.point) ? j : best));
  const rest = state.sceneData.arrays.rest_positions.data;
  const held = state.sceneData.arrays.held.data;
  const group = [];
  for (let j = 0; j < state.sim.n; j++) {
    const r = Math.hypot(rest[3 * j] - rest[3 * vertex], rest[3 * j + 1] - rest[3 * vertex + 1],
                         rest[3 * j + 2] - rest[3 * vertex + 2]);
    if (r <= DRAG_RADIUS && !held[3 * j]) group.push(j);
  }
  const normal = camera.getWorldDirection(new THREE.Vector3());
  state.drag = { vertex, group, target: hit.point.clone(),
                 plane: new THREE.Plane().setFromNormalAndCoplanarPoint(normal, hit.point) };
  controls.enabled = false;
});
renderer.domElement.addEventListener("pointermove", (event) => {
  if (state.held) {
    raycaster.setFromCamera(pointer(event), camera);
    const target = new THREE.Vector3();
    if (raycaster.ray.intersectPlane(state.held.plane, target)) {
      state.sim.moveObstacle(state.held.index, target.add(state.held.offset).toArray());
    }
    return;
  }
  if (!state.drag) return;
  raycaster.setFromCamera(pointer(event), camera);
  const target = new THREE.Vector3();
  if (raycaster.ray.intersectPlane(state.drag.plane, target)) state.drag.target = target;
});
window.addEventListener("pointerup", () => {
  state.drag = null;
  state.held = null;
  controls.enabled = true;
});

ui.pause.addEventListener("click", () => {
  state.paused = !state.paused;
  ui.pause.textContent = state.paused ? "run" : "pause";
});
ui.reset.addEventListener("click", () => { if (state.sim) { state.sim.reset(); updateBody(); } });
ui.carry.addEventListener("change", () => { state.carry = ui.carry.checked; });
ui.angle.addEventListener("input", () => {
  const angles = state.sceneData.header.fiber_angles;
  if (!angles) return;
  const angle = angles[Number(ui.angle.value)];
  ui.angleValue.textContent = String(angle);
  state.sim.setFiberAngle(angle);
  buildControls();
});
ui.stepper.addEventListener("change", async () => {
  try {
    await openScene(ui.scene.value, state.sim ? state.sim.fiberAngle : null);
  } catch (err) {
    say(String(err.message || err));
  }
});
ui.scene.addEventListener("change", async () => {
  try {
    await openScene(ui.scene.value, state.sim ? state.sim.fiberAngle : null);
  } catch (err) {
    say(String(err.message || err));
  }
});
ui.pause.textContent = state.paused ? "run" : "pause";

// what the end-to-end test drives: run(checkpoints, carry) from rest under gravity to the last
// checkpoint, the held end carried (carryBase) where carry is true, returning the positions
// (flat, float64) at each checkpoint step, the mean ms per step and each step's base (null:
// not carried)
window.anisognn = {
  ready: false, error: null,
  async run(checkpoints, carry = false) {
    state.paused = true;
    while (state.busy) await new Promise((resolve) => setTimeout(resolve, 5));
    state.carry = carry;
    ui.carry.checked = carry;
    state.sim.reset();
    const positions = [];
    let total = 0;
    for (const step of checkpoints) {
      state.times = [];
      await advance(step - state.sim.steps);
      total += state.times.reduce((a, b) => a + b, 0);
      positions.push(Array.from(state.sim.x));
    }
    updateBody();
    renderer.render(world, camera);
    const carried = carry && state.sim.framed;
    const bases = [];
    for (let k = 1; k <= state.sim.steps; k++) bases.push(carried ? carryBase(k * state.sim.dt) : null);
    return { positions, msPerStep: total / state.sim.steps, fiberAngle: state.sim.fiberAngle,
             n: state.sim.n, bases };
  },
  // a reduced model's rollout from rest under gravity and a drag, timed step by step: the
  // force forces[k] (N, 3 numbers) on vertex `vertex` at step k; returns each step's wall time
  // (ms, the step and the positions) and, where record, the positions after every step (flat)
  async rollout(vertex, forces, record = true) {
    state.paused = true;
    while (state.busy) await new Promise((resolve) => setTimeout(resolve, 5));
    state.sim.reset();
    const positions = [], ms = [];
    const force = new Float64Array(3 * state.sim.n);
    for (const f of forces) {
      for (let c = 0; c < 3; c++) force[3 * vertex + c] = f[c];
      ms.push(await state.sim.step(force, null));
      if (record) positions.push(Array.from(state.sim.x));
    }
    updateBody();
    return { positions, ms, n: state.sim.n, fiberAngle: state.sim.fiberAngle };
  },
  // the free vertex farthest from the held ones' centroid at rest (an arm's or a tip's end),
  // and the body's weight (N) under the scene's gravity
  farthest() {
    const rest = state.sceneData.arrays.rest_positions.data;
    const held = state.sceneData.arrays.held.data;
    const masses = state.sceneData.arrays.masses.data;
    const h = [0, 0, 0];
    let count = 0, mass = 0;
    for (let j = 0; j < state.sim.n; j++) {
      mass += masses[j];
      if (!held[3 * j]) continue;
      for (let c = 0; c < 3; c++) h[c] += rest[3 * j + c];
      count += 1;
    }
    let best = 0, far = -1;
    for (let j = 0; j < state.sim.n; j++) {
      if (held[3 * j]) continue;
      const d = Math.hypot(rest[3 * j] - h[0] / count, rest[3 * j + 1] - h[1] / count,
                           rest[3 * j + 2] - h[2] / count);
      if (d > far) { far = d; best = j; }
    }
    return { vertex: best, weight: mass * Math.hypot(...state.sceneData.header.gravity) };
  },
  // the page pixel (x, y) where vertex i is drawn; the mean height (m) of the vertices
  // farthest along x (a cantilever's tip); the vertex nearest a rest point (m)
  screenOf(i) {
    const p = new THREE.Vector3().fromBufferAttribute(state.body.geometry.attributes.position, i)
      .project(camera);
    const rect = renderer.domElement.getBoundingClientRect();
    return { x: rect.left + ((p.x + 1) / 2) * rect.width,
             y: rect.top + ((1 - p.y) / 2) * rect.height };
  },
  tip() {
    const rest = state.sceneData.arrays.rest_positions.data;
    let far = -Infinity;
    for (let i = 0; i < state.sim.n; i++) far = Math.max(far, rest[3 * i]);
    const tip = [];
    for (let i = 0; i < state.sim.n; i++) if (rest[3 * i] > far - 1e-9) tip.push(i);
    return { vertices: tip,
             height: tip.reduce((sum, i) => sum + state.sim.x[3 * i + 2], 0) / tip.length };
  },
  nearest(point) {
    const rest = state.sceneData.arrays.rest_positions.data;
    let best = 0, distance = Infinity;
    for (let i = 0; i < state.sim.n; i++) {
      const d = Math.hypot(rest[3 * i] - point[0], rest[3 * i + 1] - point[1],
                           rest[3 * i + 2] - point[2]);
      if (d < distance) { best = i; distance = d; }
    }
    return best;
  },
  scene() { return state.sceneData ? state.sceneData.header.scene || state.name : null; },
  // a reduced model's rollout from rest under gravity with its controls set before each step
  // to schedule[k] (one value per control) and, where moves[k] is [i, x, y, z], obstacle i
  // moved there; the positions after every step (flat) and the obstacles' at the end
  async controlled(schedule, moves = []) {
    state.paused = true;
    while (state.busy) await new Promise((resolve) => setTimeout(resolve, 5));
    state.sim.reset();
    state.times = [];
    const positions = [];
    for (const [k, values] of schedule.entries()) {
      if (moves[k]) state.sim.moveObstacle(moves[k][0], moves[k].slice(1));
      state.sim.setControls(values);
      state.times.push(await state.sim.step(null, null));
      positions.push(Array.from(state.sim.x));
    }
    updateBody();
    return { positions, controls: state.sim.controls, n: state.sim.n,
             obstacles: (state.sim.obstacles || []).map((_, i) => state.sim.obstaclePosition(i)) };
  },
  // move control i's slider to value as a user would (its input event); the controls' values
  // the model then holds
  slide(i, value) {
    const input = ui.controls.querySelectorAll("input")[i];
    input.value = String(value);
    input.dispatchEvent(new Event("input"));
    return state.sim.controlValues();
  },
  stepper() {
    return state.sim instanceof ModelSimulation ? "reduced" : "network";
  },
  stats() { return ui.stats.textContent; },
  resume() { state.paused = false; state.lastFrame = null; },
  pause() { state.paused = true; },
};

requestAnimationFrame(frame);
start();
