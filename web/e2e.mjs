// Drive the page in a real headless Chromium (the distribution's, no browser download):
//   node e2e.mjs BASE_URL OUT_DIR [CHECKPOINTS]
// Writes OUT_DIR/page.png (the cantilever at the last checkpoint) and OUT_DIR/result.json: the
// positions of the cantilever rolled from rest under gravity (fiber angle 45) at each
// checkpoint step (comma-separated, default 1,10,50,100,200), the in-browser ms per step, the
// messages the page shows for a file that is not a model and for a scene the model cannot
// step, the tip height before and during a drag upwards, and whether the other scenes (chosen
// from the menu) step; then the same with the reduced models (OUT_DIR/reduced.png), and the
// T's framed model, its foot carried, at steps 1, 10 and 50 (with each step's base) and the
// validation the page states; the cantilever's reduced model and the T's and Y's framed ones
// under a swinging drag (every step's positions), and each step's time over a longer drag; the
// tentacle's reduced model with its four controls set every step, and a slider moved.
import fs from "node:fs";
import path from "node:path";
import { chromium } from "playwright-core";

const [base, out, checkpointsArg] = process.argv.slice(2);
const checkpoints = (checkpointsArg || "1,10,50,100,200").split(",").map(Number);
const FRAMED_CHECKPOINTS = [1, 10, 50];
// the reduced models' drag: DRAG_STEPS steps recorded, then TIMED_STEPS timed
const DRAG_STEPS = 200;
const TIMED_STEPS = 300;
// the tentacle's controlled rollout
const CONTROL_STEPS = 100;

// forces (N) per step on one vertex: 0.3 of the body's weight turning in the x-z plane (a
// period of 80 steps) for the first three quarters of the steps, then released
function swing(steps, weight) {
  return Array.from({ length: steps }, (_, k) => {
    const a = (2 * Math.PI * k) / 80, f = k < (3 * steps) / 4 ? 0.3 * weight : 0;
    return [f * Math.sin(a), 0, 0.5 * f * Math.cos(a)];
  });
}
const executablePath = process.env.CHROMIUM || "/usr/bin/chromium";
fs.mkdirSync(out, { recursive: true });

const browser = await chromium.launch({
  executablePath,
  args: ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--use-gl=swiftshader", "--enable-unsafe-swiftshader"],
});
const result = {};
try {
  const page = await browser.newPage({ viewport: { width: 960, height: 640 } });
  const logs = [];
  page.on("console", (msg) => logs.push(msg.text()));
  page.on("pageerror", (err) => logs.push(String(err)));
  await page.goto(`${base}/index.html?scene=cantilever&angle=45&paused=1`);
  await page.waitForFunction(() => window.anisognn && (window.anisognn.ready ||
                                                        window.anisognn.error), null,
                             { timeout: 120000 });
  const error = await page.evaluate(() => window.anisognn.error);
  if (error) throw new Error(`the page did not start: ${error}\n${logs.join("\n")}`);
  const run = await page.evaluate((k) => window.anisognn.run(k), checkpoints);
  Object.assign(result, run, { checkpoints });
  await page.screenshot({ path: path.join(out, "page.png") });

  // a drag: press on the front face near the tip (the vertex at rest 1 cm from the free end,
  // mid-height) and pull the pointer 80 pixels up for a second of real time; the tip must rise
  // above where gravity alone holds it
  result.drag = await dragUp(page);

  // every other scene loads from the scene menu and steps without a message
  result.scenes = {};
  for (const name of ["cylinder", "t", "y"]) {
    await page.selectOption("#scene", name);
    await page.waitForFunction((n) => window.anisognn.scene() === n, name, { timeout: 60000 });
    const run = await page.evaluate(() => window.anisognn.run([5]));
    result.scenes[name] = { n: run.n, message: await page.textContent("#message"),
                            finite: run.positions[0].every(Number.isFinite) };
  }

  // the reduced models, picked from the stepper menu: every scene steps without a message, the
  // cantilever rolls out from rest (compared with runtime.py's ReducedSimulator) and rises when
  // dragged up
  await page.selectOption("#stepper", "reduced");
  await page.waitForFunction(() => window.anisognn.stepper() === "reduced", null,
                             { timeout: 60000 });
  result.reducedScenes = {};
  result.drags = {};
  result.stepTimes = {};
  for (const name of ["cylinder", "t", "y", "cantilever"]) {
    await page.selectOption("#scene", name);
    await page.waitForFunction((n) => window.anisognn.scene() === n, name, { timeout: 60000 });
    const run = await page.evaluate(() => window.anisognn.run([5]));
    result.reducedScenes[name] = { n: run.n, message: await page.textContent("#message"),
                                   finite: run.positions[0].every(Number.isFinite) };
    if (name !== "cylinder") {
      // the cantilever's reduced model and the T's and Y's framed ones under a swinging drag,
      // every step's positions (compared with the numpy runtimes), then timed alone
      const far = await page.evaluate(() => window.anisognn.farthest());
      const forces = swing(DRAG_STEPS, far.weight);
      const run = await page.evaluate(([v, f]) => window.anisognn.rollout(v, f),
                                      [far.vertex, forces]);
      result.drags[name] = { vertex: far.vertex, forces, positions: run.positions,
                             fiberAngle: run.fiberAngle };
      const timed = await page.evaluate(([v, f]) => window.anisognn.rollout(v, f, false),
                                        [far.vertex, swing(TIMED_STEPS, far.weight)]);
      result.stepTimes[name] = timed.ms;
    }
    if (name === "t") {
      // the T's framed model from rest, its foot carried (compared with runtime.py's
      // FramedSimulator, stepped with the same bases)
      result.framed = await page.evaluate((k) => window.anisognn.run(k, true), FRAMED_CHECKPOINTS);
      result.framed.stats = await page.evaluate(() => window.anisognn.stats());
    }
  }
  result.reduced = await page.evaluate((k) => window.anisognn.run(k), checkpoints);
  await page.screenshot({ path: path.join(out, "reduced.png") });
  result.reducedDrag = await dragUp(page);

  // the tentacle's reduced model, its four bands of fibers set before every step (compared
  // with runtime.py's ReducedSimulator under the same controls), and a slider moved as a user
  // would
  await page.selectOption("#scene", "tentacle");
  await page.waitForFunction(() => window.anisognn.scene() === "tentacle", null,
                             { timeout: 60000 });
  const schedule = Array.from({ length: CONTROL_STEPS }, (_, k) =>
    [0.05 * (1 - Math.cos(k / 8)), 0, 0.05 * (1 - Math.cos(k / 6)), 0.02 * (1 - Math.cos(k / 10))]);
  // the ball (obstacle 1) pushed 2 mm a step toward the tentacle from step 20 to step 40
  const moves = Array.from({ length: CONTROL_STEPS }, (_, k) =>
    (k >= 20 && k < 40 ? [1, 0.13, 0.05 - 0.002 * (k - 19), -0.01] : null));
  result.tentacle = await page.evaluate(([s, m]) => window.anisognn.controlled(s, m),
                                        [schedule, moves]);
  result.tentacle.schedule = schedule;
  result.tentacle.moves = moves;
  result.tentacle.message = await page.textContent("#message");
  result.tentacle.sliders = await page.locator("#controls input").count();
  result.tentacle.slid = await page.evaluate(() => window.anisognn.slide(1, 0.07));
  await page.screenshot({ path: path.join(out, "tentacle.png") });

  // a file that is not a model
  const bad = await browser.newPage();
  await bad.route("**/models/bad.onnx", (route) => route.fulfill({ body: "not a model" }));
  await bad.goto(`${base}/index.html?model=models/bad.onnx`);
  await bad.waitForFunction(() => document.getElementById("message").textContent.length > 0,
                            null, { timeout: 60000 });
  result.bad_model_message = await bad.textContent("#message");

  // a scene whose arrays the model cannot take: the vertex arrays cut to half the vertices
  const cut = await browser.newPage();
  await cut.route("**/scenes/cantilever.json", async (route) => {
    const response = await route.fetch();
    const header = await response.json();
    header.n = Math.floor(header.n / 2);
    for (const name of ["rest_positions", "fixed", "fixed_positions", "mass", "masses",
                        "incoming", "incoming_weights", "corners", "held"]) {
      header.arrays[name].shape[0] = header.n;
    }
    await route.fulfill({ response, json: header });
  });
  await cut.goto(`${base}/index.html?scene=cantilever`);
  await cut.waitForFunction(() => document.getElementById("message").textContent.length > 0,
                            null, { timeout: 60000 });
  result.cut_scene_message = await cut.textContent("#message");

  // a reduced model's file whose array W4 at fiber angle 45 claims another dtype: the C
  // runtime's message, shown on the page
  const shifted = await browser.newPage();
  await shifted.route("**/scenes/cantilever-reduced.json", async (route) => {
    const response = await route.fetch();
    const header = await response.json();
    header.arrays["W4@45"].dtype = "float32";
    await route.fulfill({ response, json: header });
  });
  await shifted.goto(`${base}/index.html?scene=cantilever&stepper=reduced&angle=45`);
  await shifted.waitForFunction(() => document.getElementById("message").textContent.length > 0,
                                null, { timeout: 60000 });
  result.bad_reduced_message = await shifted.textContent("#message");
} finally {
  await browser.close();
}

// press on the front face near the cantilever's tip (the vertex at rest 1 cm from the free
// end, mid-height), pull the pointer 80 pixels up for a second of real time: the tip heights
// before and while pulled
async function dragUp(page) {
  const before = await page.evaluate(() => window.anisognn.tip());
  const at = await page.evaluate(() => window.anisognn.screenOf(
    window.anisognn.nearest([0.09, -0.01, 0.0])));
  await page.evaluate(() => window.anisognn.resume());
  await page.mouse.move(at.x, at.y);
  await page.mouse.down();
  await page.mouse.move(at.x, at.y - 80, { steps: 10 });
  await page.waitForTimeout(1000);
  const pulled = await page.evaluate(() => window.anisognn.tip());
  await page.mouse.up();
  await page.evaluate(() => window.anisognn.pause());
  return { before: before.height, pulled: pulled.height };
}
fs.writeFileSync(path.join(out, "result.json"), JSON.stringify(result));
console.log(`in-browser step: ${result.msPerStep.toFixed(2)} ms over ` +
            `${checkpoints[checkpoints.length - 1]} steps`);
