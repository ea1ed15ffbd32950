"""anisognn training machinery: learning on a fixed scene, exact resume after a kill, the NaN
guard, data-parallel training with torchrun, checkpoints, rollout and bad input."""
import json
import os
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import torch

import anisofem as af
import anisognn
from anisognn import checkpoint, train
from anisognn.loss import BatchPotential
from anisognn.model import GraphNet, ModelConfig
from anisognn.sampler import Sample, Sampler

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TINY = {"model": {"latent": 16, "steps": 2},
        "sampler": {"deformed_probability": 0.0},
        "train": {"iterations": 12, "batch_size": 2, "log_every": 1, "eval_every": 0,
                  "checkpoint_every": 3, "normalization_samples": 4, "learning_rate": 1e-3}}


# the other loss and own-rollout training, for the exact-resume test
RICH = {**TINY, "train": {**TINY["train"], "newton_weight": 10.0, "normalize": True,
                          "rollout_probability": 0.5, "rollout_steps": 3}}


def write_config(path, raw):
    lines = []
    for section, values in raw.items():
        lines.append(f"[{section}]")
        lines += [f"{k} = {json.dumps(v)}" for k, v in values.items()]
    path.write_text("\n".join(lines) + "\n")
    return str(path)


def read_log(out):
    with open(os.path.join(out, "log.jsonl")) as f:
        return [json.loads(line) for line in f]


def test_training_on_a_fixed_scene_closes_most_of_the_energy_gap():
    """300 iterations on one cantilever state: the gap G(net) - G(newton) shrinks >= 20x
    (measured: 3.2e-4 J -> 3.9e-6 J, 81x; 2e-8 J after 600 iterations)."""
    torch.manual_seed(0)
    mesh = af.box_beam(cells=(5, 2, 2))
    scene = af.Scene(mesh, fixed=mesh.vertices[:, 0] <= 1e-9, gravity=[0, 0, -9.81])
    x = scene.initial_positions()
    sample = Sample(scene, x, np.zeros_like(x))
    model = GraphNet(ModelConfig(latent=32, steps=3))
    train.fit_normalization(model, [sample])
    batch = train.make_batch([sample], 0.02, "cpu")
    best = af.step(scene, x, sample.v, 0.02).newton.energy
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    gaps = []
    for _ in range(300):
        loss, _ = train.batch_loss(model, batch, 0.02)
        gaps.append(float(loss.detach()) - best)
        opt.zero_grad()
        loss.backward()
        opt.step()
    print(f"energy gap: start {gaps[0]:.3e} J, end {gaps[-1]:.3e} J, "
          f"factor {gaps[0] / gaps[-1]:.1f}")
    assert gaps[0] > 0 and gaps[-1] < gaps[0] / 20


def test_the_train_command_seed_overrides_the_config_seed(tmp_path):
    """`train --seed N` trains what a config with [train] seed = N trains, and seeds differ."""
    from anisognn import cli
    config = write_config(tmp_path / "tiny.toml", TINY)
    seeded = write_config(tmp_path / "seeded.toml",
                          {**TINY, "train": {**TINY["train"], "seed": 1}})
    by_file = train.train(train.load_config(seeded, out=str(tmp_path / "file")),
                          progress=False)[1]
    cli.main(["train", "--config", config, "--out", str(tmp_path / "flag"), "--seed", "1",
              "--no-progress"])
    by_flag = [r for r in read_log(tmp_path / "flag") if r.get("event") == "done"][0]
    unseeded = train.train(train.load_config(config, out=str(tmp_path / "zero")),
                           progress=False)[1]
    assert by_flag["digest"] == by_file["digest"] != unseeded["digest"]


def test_resume_after_kill_gives_the_parameters_of_an_uninterrupted_run(tmp_path):
    config = write_config(tmp_path / "rich.toml", RICH)
    os.makedirs(tmp_path / "whole")
    (tmp_path / "whole" / "log.jsonl").write_text('{"iteration": 7, "loss": -1.0}\n')  # stale
    whole = train.train(train.load_config(config, out=str(tmp_path / "whole")),
                        progress=False)[1]
    assert -1.0 not in [r.get("loss") for r in read_log(tmp_path / "whole")]
    out = str(tmp_path / "killed")
    proc = subprocess.Popen([sys.executable, "-m", "anisognn", "train", "--config", config,
                             "--out", out, "--no-progress"], cwd=ROOT)
    ckpt = os.path.join(out, "checkpoint.pt")
    deadline = time.time() + 120
    while time.time() < deadline and proc.poll() is None:
        if os.path.exists(ckpt) and checkpoint.read(ckpt)["iteration"] >= 3:
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    stopped_at = checkpoint.read(ckpt)["iteration"]
    assert 3 <= stopped_at < 12, "the run was not interrupted mid-way"
    resumed = train.train(train.load_config(config, out=out), progress=False)[1]
    assert resumed["resumed_from"] == stopped_at
    assert resumed["digest"] == whole["digest"]
    logged = [r["iteration"] for r in read_log(out) if "loss" in r and "event" not in r]
    assert logged == list(range(1, 13))  # no lost or repeated lines
    assert any(r.get("advanced") for r in read_log(out))  # own rollouts were trained on


def test_a_finished_run_extends_to_the_longer_run_from_a_copied_folder(tmp_path):
    """6 iterations, the folder copied, then extended to 12: the parameters of a 12-iteration
    run; fewer iterations than the checkpoint's, or another setting, are refused."""
    config = write_config(tmp_path / "tiny.toml", TINY)
    whole = train.train(train.load_config(config, out=str(tmp_path / "whole")),
                        progress=False)[1]
    short = str(tmp_path / "short")
    first = train.train(train.load_config(config, out=short, iterations=6), progress=False)[1]
    assert first["digest"] != whole["digest"]
    moved = str(tmp_path / "moved")
    shutil.copytree(short, moved)
    longer = train.train(train.load_config(config, out=moved), progress=False)[1]
    assert longer["resumed_from"] == 6 and longer["digest"] == whole["digest"]
    logged = [r["iteration"] for r in read_log(moved) if "loss" in r and "event" not in r]
    assert logged == list(range(1, 13))
    with pytest.raises(ValueError, match=r"at iteration 6, past \[train\] iterations = 4"):
        train.train(train.load_config(config, out=short, iterations=4), progress=False)
    with pytest.raises(ValueError, match="different configuration"):
        train.train(train.load_config(config, out=short, learning_rate=2e-3), progress=False)


def test_own_rollout_advances_by_the_model_and_keeps_runaway_starts():
    """A model that predicts a = 0 flies free: x + k dt v, v unchanged (held components stay);
    one that flings vertices away leaves the samples at their start."""
    mesh = af.box_beam(cells=(3, 1, 1))
    scene = af.Scene(mesh, fixed=mesh.vertices[:, 0] <= 1e-9, gravity=[0, 0, -9.81])
    rng = np.random.default_rng(0)
    x = scene.initial_positions()
    v = np.where(scene.fixed_mask, 0.0, rng.normal(size=x.shape) * 0.01)
    samples = [Sample(scene, x, v), Sample(scene, x + 1e-4 * scene.fixed_mask, v)]
    model = GraphNet(ModelConfig(latent=8, steps=1))  # zero decoder: a = 0
    graph = train.batch_graph(samples, "cpu")
    out, advanced = train.own_rollout(model, samples, graph, 3, 0.02)
    assert advanced == 2
    free = ~scene.fixed_mask
    for s, o in zip(samples, out):
        assert np.allclose(o.x[free], s.x[free] + 0.06 * v[free], rtol=0, atol=1e-15)
        assert np.array_equal(o.x[scene.fixed_mask], scene.fixed_positions[scene.fixed_mask])
        assert np.allclose(o.v[free], v[free], rtol=0, atol=1e-12) and o.scene is scene
    torch.nn.init.constant_(model.decoder[-1].bias, 1e3)  # 1e3 * accel_scale m/s^2
    out, advanced = train.own_rollout(model, samples, graph, 3, 0.02)
    assert advanced == 0 and all(o is s for o, s in zip(out, samples))


def test_nan_guard_stops_and_keeps_the_last_good_checkpoint(tmp_path, monkeypatch):
    config = train.make_config(TINY, out=str(tmp_path / "nan"))
    real = BatchPotential.energy_gradient
    calls = {"n": 0}

    def poisoned(self, x, *args):
        calls["n"] += 1
        energy, grad = real(self, x, *args)
        return (float("nan"), grad) if calls["n"] == 5 else (energy, grad)
    monkeypatch.setattr(BatchPotential, "energy_gradient", poisoned)
    with pytest.raises(train.TrainingDiverged, match="iteration 5: loss nan.*last good"):
        train.train(config, progress=False)
    kept = checkpoint.read(os.path.join(config.train.out, "checkpoint.pt"))
    assert kept["iteration"] == 3
    assert all(torch.isfinite(t).all() for t in kept["model"].values())
    assert read_log(config.train.out)[-1]["event"] == "diverged"


def test_two_process_torchrun_keeps_ranks_identical(tmp_path):
    raw = {**TINY, "train": {**TINY["train"], "iterations": 4, "device": "cpu"}}
    config = write_config(tmp_path / "ddp.toml", raw)
    out = str(tmp_path / "ddp")
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    run = subprocess.run([sys.executable, "-m", "torch.distributed.run", "--standalone",
                          "--nproc_per_node", "2", os.path.join(ROOT, "tests", "torchrun_train.py"),
                          "train", "--config", config, "--out", out, "--no-progress"],
                         cwd=ROOT, env=env, timeout=300, capture_output=True, text=True)
    assert run.returncode == 0, run.stderr[-3000:]
    assert "terminate called" not in run.stderr
    # the group is freed before exit (a live one aborts the exit now and then), on both ranks
    for rank in (0, 1):
        assert f"rank {rank}: other references to the group: 0\n" in run.stdout, run.stdout
    assert run.stdout.count("done:") == 1             # only rank 0 reports
    done = read_log(out)[-1]
    assert done["event"] == "done" and len(done["rank_digests"]) == 2
    assert done["rank_digests"][0] == done["rank_digests"][1] == done["digest"]


def test_a_torchrun_process_without_a_gpu_of_its_own_is_told_so(monkeypatch):
    """The GPU branch of the data-parallel set-up, reached on any machine: a process whose
    LOCAL_RANK has no GPU gets the error that says what to do (here: no GPU at all)."""
    monkeypatch.setenv("WORLD_SIZE", "2")
    monkeypatch.setenv("LOCAL_RANK", "0")
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 0)
    with pytest.raises(ValueError, match=r"torchrun process 0 has no GPU of its own \(0 found\)"):
        with train._distributed(torch.device("cuda")):
            pass


def test_config_errors_name_the_problem(tmp_path):
    with pytest.raises(ValueError, match=r"\[train\] has unknown keys \['iteratons'\]"):
        train.make_config({"train": {"iteratons": 3}})
    with pytest.raises(ValueError, match="unknown sections"):
        train.make_config({"modle": {}})
    with pytest.raises(ValueError, match="model.dt .* sampler.dt"):
        train.make_config({"model": {"dt": 0.01}})
    with pytest.raises(ValueError, match=r"\[train\] energy_weight: must be >= 0"):
        train.make_config({"train": {"energy_weight": -1.0}})
    with pytest.raises(ValueError, match=r"rollout_probability: must be in \[0, 1\]"):
        train.make_config({"train": {"rollout_probability": 1.5}})
    with pytest.raises(ValueError, match="rollout_steps: must be an integer >= 1"):
        train.make_config({"train": {"rollout_steps": 0}})
    with pytest.raises(ValueError, match="at least one must be > 0"):
        train.make_config({"train": {"energy_weight": 0.0}})
    with pytest.raises(ValueError, match=r"\[sampler\] has unknown keys \['noise_modes'\]"):
        train.make_config({"sampler": {"noise_modes": 0}})
    with pytest.raises(ValueError,
                       match=r"\[sampler\] equilibrium_probability: must be in \[0, 1\]"):
        train.make_config({"sampler": {"equilibrium_probability": 1.5}})
    with pytest.raises(ValueError, match=r"\[sampler\] noise_position: must be >= 0"):
        train.make_config({"sampler": {"noise_position": -1e-3}})
    bad = tmp_path / "bad.toml"
    bad.write_text("[train\niterations = 3")
    with pytest.raises(ValueError, match="not valid TOML"):
        train.load_config(bad)


@pytest.fixture(scope="module")
def saved_model(tmp_path_factory):
    torch.manual_seed(0)
    model = GraphNet(ModelConfig(latent=16, steps=2))
    torch.nn.init.normal_(model.decoder[-1].weight, std=1e-2)
    train.fit_normalization(model, [Sampler(0).sample(i) for i in range(4)])
    path = str(tmp_path_factory.mktemp("model") / "model.pt")
    checkpoint.save(path, model)
    return model, path


def cantilever():
    mesh = af.box_beam(cells=(5, 2, 2))
    return af.Scene(mesh, af.Material(1e5, 0.48, 1000.0, [1, 0, 0], 1e5),
                    fixed=mesh.vertices[:, 0] <= 1e-9, gravity=[0, 0, -9.81])


def test_load_and_rollout(saved_model):
    model, path = saved_model
    loaded = anisognn.load(path)
    assert not loaded.training and loaded.config == model.config
    scene = cantilever()
    a = anisognn.rollout(model.eval(), scene, 5)
    b = anisognn.rollout(loaded, scene, 5)
    assert a.shape == (6, scene.mesh.n_vertices, 3) and np.array_equal(a, b)
    held = scene.fixed_mask
    assert (a[:, held] == scene.fixed_positions[held]).all()
    assert np.abs(a[-1] - a[0])[~held].max() > 0  # the free part moves


def test_rollout_bad_input(saved_model):
    model, _ = saved_model
    scene = cantilever()
    n = scene.mesh.n_vertices
    with pytest.raises(ValueError, match="trained for dt = 0.02 s"):
        anisognn.rollout(model, scene, 3, dt=0.01)
    x0 = scene.initial_positions()
    x0[3, 1] = np.nan
    with pytest.raises(ValueError, match="x0: contains NaN"):
        anisognn.rollout(model, scene, 3, x0=x0)
    with pytest.raises(ValueError, match=r"v0: expected shape \(%d, 3\)" % n):
        anisognn.rollout(model, scene, 3, v0=np.zeros((n, 2)))
    with pytest.raises(TypeError, match="scene: expected an anisofem.Scene"):
        anisognn.rollout(model, scene.mesh, 3)
    with pytest.raises(ValueError, match="steps: must be >= 0"):
        anisognn.rollout(model, scene, -1)
    with pytest.raises(ValueError, match="no tetrahedra"):  # a mesh without edges
        af.TetMesh(np.eye(4, 3), np.zeros((0, 4), int))


def test_bad_checkpoints_give_clear_errors(saved_model, tmp_path):
    _, path = saved_model
    garbage = tmp_path / "garbage.pt"
    garbage.write_bytes(b"not a checkpoint at all")
    with pytest.raises(ValueError, match="not a readable torch file"):
        anisognn.load(str(garbage))
    truncated = tmp_path / "truncated.pt"
    truncated.write_bytes(open(path, "rb").read()[:2000])
    with pytest.raises(ValueError, match="not a readable torch file"):
        anisognn.load(str(truncated))
    foreign = tmp_path / "foreign.pt"
    torch.save({"state_dict": {"w": torch.zeros(2)}}, foreign)
    with pytest.raises(ValueError, match="not an anisognn checkpoint"):
        anisognn.load(str(foreign))
    pickled = tmp_path / "pickled.pt"
    torch.save({"format": checkpoint.FORMAT, "evil": object()}, pickled)
    with pytest.raises(ValueError, match="not a readable torch file"):  # weights_only refuses
        anisognn.load(str(pickled))
    wrong = checkpoint.read(path)
    wrong["config"]["latent"] = 8
    torch.save(wrong, tmp_path / "wrong.pt")
    with pytest.raises(ValueError, match="weights do not fit the config"):
        anisognn.load(str(tmp_path / "wrong.pt"))
    with pytest.raises(FileNotFoundError, match="no such file"):
        anisognn.load(str(tmp_path / "missing.pt"))


def test_galerkin_outside_training_trains_the_same_network(tmp_path):
    """[train] through_galerkin = false trains exactly what the config without galerkin does
    (same parameters bit for bit, own rollouts included), and the finished model takes the
    Galerkin step; through_galerkin = true trains something else."""
    rich = {**RICH, "train": {**RICH["train"], "iterations": 4}}
    digests, steps = {}, {}
    for name, galerkin, through in (("plain", False, True), ("outside", True, False),
                                    ("through", True, True)):
        raw = {**rich, "model": {**rich["model"], "galerkin": galerkin},
               "train": {**rich["train"], "through_galerkin": through}}
        model, summary = train.train(train.make_config(raw, out=str(tmp_path / name)),
                                     progress=False)
        digests[name] = summary["digest"]
        saved = anisognn.load(str(tmp_path / name / "model.pt"))
        assert saved.config.galerkin == galerkin
        steps[name] = anisognn.rollout(saved, scene_for_rollout(), 3)
    assert digests["outside"] == digests["plain"]
    assert digests["through"] != digests["plain"]
    assert np.abs(steps["outside"] - steps["plain"]).max() > 1e-9  # the step differs


def scene_for_rollout():
    mesh = af.box_beam(cells=(3, 2, 1))
    return af.Scene(mesh, fixed=mesh.vertices[:, 0] <= 1e-9, gravity=[0, 0, -9.81])
