"""The framed reduced model (anisofem.reduced.framed): the body cut into domains at its
junctions, each domain's energy exact in its own frame, derivatives against central
differences at ordinary and extreme parameters, backward Euler without energy gain, and
the T's validation on unseen one-arm drags, where a linear basis drifts."""
import numpy as np
import pytest

import anisofem as af
from anisofem.physics.potential import Potential
from anisofem.reduced import Carry, Drag, Loads, ReducedModel
from anisofem.reduced.domains import split
from anisofem.reduced.framed import FramedModel, FramedState, rotations

FIBER = np.array([0.6, 0.0, 0.8])


def t_scene(kappa=0.0, poisson=0.48, order=1):
    mesh = af.t_shape(order=order)
    return af.Scene(mesh, af.Material(1e5, poisson, 1000.0, FIBER, kappa),
                    fixed=np.flatnonzero(mesh.vertices[:, 2] < 1e-9), gravity=(0, 0, -9.81))


def beam_scene(order=1, kappa=1e5, cells=(6, 2, 2)):
    mesh = af.box_beam((0.1, 0.02, 0.02), cells)
    mesh = mesh.raised() if order == 2 else mesh
    return af.Scene(mesh, af.Material(1e5, 0.48, 1000.0, FIBER, kappa),
                    fixed=np.flatnonzero(mesh.vertices[:, 0] < 1e-9), gravity=(0, 0, -9.81))


@pytest.fixture(scope="module")
def t_model():
    return FramedModel(t_scene(), validate=False)


def test_split_cuts_the_t_at_its_junction():
    """4 bands from the T's foot: the stem's bands, then one domain per arm (mirror images);
    every free node in a domain, the held ones in none."""
    scene = t_scene()
    labels, count = split(scene, 4)
    held = scene.fixed_mask.any(axis=1)
    assert (labels[held] == -1).all() and (labels[~held] >= 0).all()
    sizes = np.bincount(labels[labels >= 0])
    assert count == 5 and sizes[-1] == sizes[-2]
    x = scene.mesh.vertices
    arms = [x[labels == d, 0] for d in (count - 2, count - 1)]
    assert {np.sign(a.mean()) for a in arms} == {-1.0, 1.0}
    assert all(np.all(np.sign(a) == np.sign(a.mean())) for a in arms)


def test_split_labels_midside_nodes():
    """On 10-node tets every free node, midside ones included, falls into a domain."""
    scene = t_scene(order=2)
    labels, count = split(scene, 4)
    held = scene.fixed_mask.any(axis=1)
    assert count == 5 and (labels[held] == -1).all() and (labels[~held] >= 0).all()


#: a base turned 0.5 rad about (1, 2, 2) / 3 and moved: the held nodes carried rigidly
TURNED = np.hstack([rotations(np.array([[1.0, 2.0, 2.0]]) / 6)[0], [[0.01], [-0.02], [0.03]]])


def carried(model, base):
    """The rest state carried rigidly by base (3, 4) [R_g | c_g]."""
    rest = model.rest()
    D = len(model.domains)
    return FramedState(rest.c @ base[:, :3].T + base[:, 3], np.tile(base[:, :3], (D, 1, 1)),
                       rest.q, base)


def random_state(model, seed, size, base=None):
    rng = np.random.default_rng(seed)
    start = model.rest() if base is None else carried(model, base)
    return model.retract(start, rng.normal(size=model.r) * size)


def step_problem(model, seed, inertia, base=None, size=1e-3):
    """A state away from rest (its Newton unknowns about `size`; the held nodes at base), the
    step's targets (a random extra force, x_hat from two states) and the full positions of
    both."""
    rng = np.random.default_rng(seed)
    now = random_state(model, seed, size, base)
    before = model.retract(now, rng.normal(size=model.r) * 0.1 * size)
    force = rng.normal(size=model.x0.shape) * 1e-2
    history = ((now, 2.0), (before, -1.0)) if inertia else ()
    return now, before, force, model._targets(model._load(force), inertia, history)


@pytest.mark.parametrize("inertia, base", [(0.0, None), (2500.0, None), (2500.0, TURNED)])
def test_energy_is_the_full_potential_at_the_framed_positions(t_model, inertia, base):
    """The step's energy differs from the full FEM's potential (elastic, loads, inertia) at
    the model's positions by a constant: the same kinematics, no approximation in the sums;
    also with the held nodes carried by a turned and moved base."""
    model = t_model
    now, before, force, targets = step_problem(model, 1, inertia, base)
    scene = model.scene.plus_force(force)
    x_hat = 2 * model.positions(now) - model.positions(before)

    def full(state):
        x = model.positions(state)
        return (Potential(scene).energy(x)
                + 0.5 * inertia * np.sum(scene.masses[:, None] * (x - x_hat) ** 2))
    other = random_state(model, 2, 1e-3, base)
    assert (model.energy(other, targets, inertia) - model.energy(now, targets, inertia)
            == pytest.approx(full(other) - full(now), rel=1e-10))


def check_derivatives(model, inertia, seed=3, base=None, size=1e-3):
    """Every gradient component against central differences of the energy (in the Newton
    unknowns: t, theta turning R by exp([theta]), q), and 40 Hessian entries against mixed
    second differences, both Richardson-extrapolated, each Hessian entry within 1e-6 of
    sqrt(H_ii H_jj), at a state `size` away from rest (step_problem)."""
    now, _, _, targets = step_problem(model, seed, inertia, base, size)
    E, g, H = model.derivatives(now, targets, inertia)

    def e(z):
        return model.energy(model.retract(now, z), targets, inertia)
    rng = np.random.default_rng(seed)
    scale = np.abs(g).max()

    def central(a, h):
        return (e(h * a) - e(-h * a)) / (2 * h)
    for i in range(model.r):
        a = np.eye(model.r)[i]
        richardson = (4 * central(a, 5e-7) - central(a, 1e-6)) / 3
        assert richardson == pytest.approx(g[i], rel=1e-6, abs=1e-9 * scale)

    def mixed(a, b, k):
        return (e(k * a + k * b) - e(k * a - k * b) - e(-k * a + k * b)
                + e(-k * a - k * b)) / (4 * k * k)
    for i, j in rng.integers(model.r, size=(40, 2)):
        a, b = np.eye(model.r)[i], np.eye(model.r)[j]
        richardson = (4 * mixed(a, b, 5e-5) - mixed(a, b, 1e-4)) / 3
        scale = np.sqrt(abs(H[i, i] * H[j, j]))
        assert richardson == pytest.approx(H[i, j], abs=1e-6 * scale)


@pytest.mark.parametrize("inertia, base", [(0.0, None), (2500.0, None), (2500.0, TURNED)])
def test_derivatives_against_finite_differences(t_model, inertia, base):
    check_derivatives(t_model, inertia, base=base)


@pytest.mark.parametrize("case", ["nearly incompressible", "stiff fibers", "quadratic"])
def test_derivatives_at_the_extremes(case):
    """nu = 0.499, kappa = 100 E, and 10-node tets."""
    scene = {"nearly incompressible": lambda: beam_scene().with_material(
                 af.Material(1e5, 0.499, 1000.0, FIBER, 1e5)),
             "stiff fibers": lambda: beam_scene(kappa=1e7),
             "quadratic": lambda: beam_scene(order=2, cells=(3, 1, 1))}[case]()
    tip = tuple(int(i) for i in af.metrics.end_vertices(scene.mesh, 0, "max"))
    loads = Loads(drags=(Drag(tip, 0.05, directions=((0.0, 1.0, 0.0),)),))
    model = FramedModel(scene, bands=2, coordinates=6, loads=loads, validate=False)
    check_derivatives(model, 2500.0, seed=4)


@pytest.fixture(scope="module")
def cubature_model():
    """A beam whose cuts hold enough elements for the joints' cubature to pay (640 tets, 320
    joint elements), and the same model with every joint element evaluated."""
    scene = beam_scene(cells=(8, 4, 4))
    return FramedModel(scene, validate=False), FramedModel(scene, cubature=0, validate=False)


def test_joint_cubature_takes_a_weighted_few_of_the_joint_elements(cubature_model):
    model, whole = cubature_model
    c = model.cubature
    assert whole.cubature is None and c is not None
    assert c.of == whole._joint_elements.tets.shape[0] == 320
    assert model._joint_elements.tets.shape[0] == len(c.elements) <= c.of // 2
    assert (c.weights > 0).all() and c.residual <= 0.01
    assert len(model.joint_nodes) < len(whole.joint_nodes)


@pytest.mark.parametrize("inertia", [0.0, 2500.0])
def test_joint_cubature_derivatives_against_finite_differences(cubature_model, inertia):
    """At a state 1e-4 from rest (its energy 50 J): at the T's 1e-3 this beam's energy is
    3e5 J, and the differences drown in its round-off."""
    check_derivatives(cubature_model[0], inertia, seed=5, size=1e-4)


def test_joint_cubature_rolls_out_like_every_joint_element(cubature_model):
    """A sideways drag of half the beam's weight at its tip for 25 steps, then released for
    25: the tip with the cubature within 2% of its largest displacement with every joint
    element (measured 1.06%)."""
    model, whole = cubature_model
    scene = model.scene
    tip = af.metrics.end_vertices(scene.mesh, 0, "max")
    drag = np.zeros_like(model.x0)
    drag[tip, 1] = 0.5 * scene.masses.sum() * 9.81 / tip.size
    phases = ((drag, 25), (np.zeros_like(drag), 25))
    (x, ok), (y, whole_ok) = model.rollout(phases, 0.02), whole.rollout(phases, 0.02)
    assert ok and whole_ok
    moved = np.linalg.norm(y[:, tip].mean(axis=1) - model.x0[tip].mean(axis=0), axis=1).max()
    assert moved > 0.01
    assert np.linalg.norm((x - y)[:, tip].mean(axis=1), axis=1).max() < 0.02 * moved


def test_static_equilibrium_is_the_fems_under_the_scenes_load(t_model):
    """Gravity alone: within 0.5% of the full FEM's largest displacement."""
    state, report = t_model.solve()
    assert report.converged
    full = af.solve(t_model.scene).x
    u = np.linalg.norm(full - t_model.x0, axis=1).max()
    assert np.linalg.norm(t_model.positions(state) - full, axis=1).max() < 5e-3 * u


@pytest.mark.parametrize("body", ["T", "beam with a joint cubature"])
def test_backward_euler_gains_no_energy(t_model, cubature_model, body):
    """A drag of the declared size on one free end for 15 steps, then released for 35: every
    step converges, and after the release the model's total energy (its elastic energy,
    gravity's, kinetic from the step's velocity) never rises."""
    model = t_model if body == "T" else cubature_model[0]
    force = model.loads.drags[0].force(model.scene, np.array([0.0, 1.0, 0.0]))
    states, ok = model._states(((force, 15), (None, 35)), 0.02)
    xs = np.array([model.positions(s) for s in states])
    assert ok and np.isfinite(xs).all()
    statics = model._targets(model._load(None), 0.0, ())
    m = model.scene.masses[:, None]
    energy = [model.energy(states[k], statics, 0.0)
              + 0.5 * np.sum(m * ((xs[k] - xs[k - 1]) / 0.02) ** 2) for k in range(16, len(xs))]
    assert np.all(np.diff(energy) <= 1e-9 * np.abs(energy).max())
    assert energy[-1] < energy[0]


def test_t_validation_on_unseen_one_arm_drags(t_model):
    """The T held at its foot under gravity, drags of up to half its weight at either arm's
    end in any direction (the default declaration), the validation's 3 unseen cases held 25
    steps and released 25: the tip within 3% of the full FEM's (0.93% over 8 cases in
    scripts/framed_validation.py, where the linear basis of 4 modes and 16 fitted directions
    is 16% off)."""
    validation = t_model.validate()
    assert validation.converged and validation.cases == 3
    assert validation.tip_error < 0.03


def test_refuses_what_it_cannot_model():
    scene = t_scene()
    with pytest.raises(ValueError, match="bands"):
        FramedModel(scene, bands=0, validate=False)
    with pytest.raises(ValueError, match="coordinates"):
        FramedModel(scene, coordinates=0, validate=False)
    for bad in (-0.1, 1.0, float("nan"), "0.01", True):
        with pytest.raises(ValueError, match="cubature"):
            FramedModel(scene, cubature=bad, validate=False)
    with pytest.raises(ValueError, match="Neo-Hookean"):
        FramedModel(scene.with_material(af.Material(1e5, 0.48, 1000.0, model="neohookean")),
                    validate=False)
    mesh = scene.mesh
    roller = np.zeros((mesh.n_vertices, 3), bool)
    roller[mesh.vertices[:, 2] < 1e-9] = True
    roller[mesh.vertices[:, 2] > 0.08 - 1e-9, 0] = True
    with pytest.raises(ValueError, match="rollers"):
        FramedModel(af.Scene(mesh, scene.material, fixed=roller), validate=False)
    held = tuple(int(i) for i in np.flatnonzero(scene.fixed_mask.any(axis=1))[:2])
    with pytest.raises(ValueError, match="held"):
        FramedModel(scene, validate=False, loads=Loads(drags=(Drag(held, 1.0),)))


def test_step_refuses_bad_forces(t_model):
    rest = t_model.rest()
    with pytest.raises(ValueError, match="force"):
        t_model.step(rest, rest, 0.02, force=np.zeros((3, 3)))
    with pytest.raises(ValueError, match="force"):
        t_model.step(rest, rest, 0.02, force=np.full(t_model.x0.shape, np.nan))
    with pytest.raises(ValueError, match="dt"):
        t_model.step(rest, rest, 0.0)


def test_trade_rung_and_where_it_is_left_out():
    """The trade's framed rung on the T follows the exact rollout; a scene with rollers leaves
    it out with a note, the other reduced rungs kept."""
    scene = t_scene()
    result = af.trade(scene, steps=10, progress=False,
                      rungs=af.studies.rungs.fem_rungs()[:1]
                      + [af.studies.rungs.framed_rung(4, 12)])
    row = result["rungs"][1]
    assert row["name"] == "reduced framed b4 c12" and row["kind"] == "reduced"
    assert row["stable"] and row["max_error"] < 0.01
    mesh = scene.mesh
    roller = np.zeros((mesh.n_vertices, 3), bool)
    roller[mesh.vertices[:, 2] < 1e-9] = True
    roller[mesh.vertices[:, 2] > 0.08 - 1e-9, 0] = True
    notes = []
    rungs = [af.studies.rungs.framed_rung(4, 12), af.studies.rungs.reduced_rung(4, 16)]
    kept = af.studies.rungs.representable(rungs, af.Scene(mesh, scene.material, fixed=roller),
                                          notes)
    assert [r.name for r in kept] == ["reduced m4 s16"]
    partial = int((roller.any(axis=1) & ~roller.all(axis=1)).sum())
    assert partial == 33 and notes == [
        f"framed rungs not run: fixed: the framed model holds whole nodes; {partial} nodes are "
        f"held along some axes only (rollers)"]


def test_element_subset_colors_its_own_blocks():
    """A subset of elements has an assembly coloring of its own: its blocks cover each element
    once and no two blocks of one color share a node. The subset here takes a 6,400-tet beam's
    assembly blocks 0, 5 and 1 in that order, so its first and third blocks touch, where the
    whole mesh's coloring gives blocks 0 and 2 one color (and two threads would scatter into
    the same nodes)."""
    from anisofem.physics.mesh import ASSEMBLY_BLOCK as B
    elements = af.Scene(af.box_beam((0.2, 0.02, 0.02), (20, 8, 8)),
                        af.Material(1e5, 0.48, 1000.0), fixed=[0]).elements
    rows = np.concatenate([np.arange(k * B, (k + 1) * B) for k in (0, 5, 1)])
    nodes, local = np.unique(elements.tets[rows], return_inverse=True)
    sub = elements.subset(rows, local.reshape(rows.size, -1))
    m = sub.tets.shape[0]
    assert m == rows.size and np.array_equal(nodes[sub.tets], elements.tets[rows])
    covered = np.concatenate([np.arange(s, min(s + B, m)) for s in sub.block_starts])
    assert np.array_equal(np.sort(covered), np.arange(m))
    for c in range(sub.color_ptr.size - 1):
        starts = sub.block_starts[sub.color_ptr[c]:sub.color_ptr[c + 1]]
        seen = [set(sub.tets[s:s + B, :4].ravel()) for s in starts]
        assert sum(len(v) for v in seen) == len(set().union(*seen))


def swung_base(k, dt=0.02):
    """The base at step k: turned about x by up to 0.5 rad and moved 3 cm along y over 0.5 s
    (a smooth start and stop), then held."""
    s = 0.5 - 0.5 * np.cos(np.pi * min(k * dt / 0.5, 1.0))
    return np.hstack([rotations(np.array([[0.5 * s, 0.0, 0.0]]))[0], [[0.0], [0.03 * s], [0.0]]])


def test_a_moving_base_carries_the_body_as_in_the_full_fem(t_model):
    """The T's foot turned 0.5 rad and moved 3 cm in 0.5 s, then held: 50 steps within 2% of
    the full FEM's rollout with the same prescribed motion (over its largest deformation from
    the base's rigid motion); the held nodes exactly where the base puts them."""
    model, scene = t_model, t_model.scene
    x0 = scene.mesh.vertices
    x, v = x0.copy(), np.zeros_like(x0)
    now = before = model.rest()
    worst = size = 0.0
    for k in range(1, 51):
        base = swung_base(k)
        rigid = x0 @ base[:, :3].T + base[:, 3]
        full = af.step(scene.held_at(rigid), x, v, 0.02)
        x, v = full.x, full.v
        after, report = model.step(now, before, 0.02, base=base)
        assert report.converged
        now, before = after, now
        y = model.positions(now)
        held = scene.fixed_mask.any(axis=1)
        assert np.abs(y[held] - rigid[held]).max() < 1e-12
        worst = max(worst, np.abs(y - x).max())
        size = max(size, np.abs(x - rigid).max())
    assert size > 0.01 and worst < 0.02 * size
    with pytest.raises(ValueError, match="base: its first 3 columns must be a rotation"):
        model.step(now, before, 0.02, base=np.hstack([2 * np.eye(3), np.zeros((3, 1))]))
    with pytest.raises(ValueError, match="base"):
        model.step(now, before, 0.02, base=np.eye(3))


def test_validation_covers_a_declared_carry(t_model):
    """The T built for its default drags and a carry of its foot (a turn of up to 30 degrees
    and a move of up to 3 cm in 0.5 s): within 3% of the full FEM on 3 unseen drags with
    carries (the full FEM's held vertices moved as the model's base)."""
    drags = t_model.loads.drags
    model = FramedModel(t_model.scene, validate=False,
                        loads=Loads(drags, carry=Carry(turn=30, move=0.03, seconds=0.5)))
    v = model.validate()
    assert v.cases == 3 and v.converged and v.tip_error < 0.03
