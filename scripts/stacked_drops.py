"""Bodies dropped onto each other, by self-contact (ipctk): the 0.2 m beam, the T and the rod
(anisofem.studies.drops, Neo-Hookean), one lying on the ground, the other dropped across it
from 2 cm, at 1, 10 and 100 g and dt 0.005, 0.02 and 0.05 s (friction 0.3).

    python scripts/stacked_drops.py [--json results/stacked_drops.json]

For each rollout: every step converged, Newton iterations (the most in a step, and in all),
the nearest the two surfaces and the ground came, inverted elements, and how many of the
points the solves evaluated (every Newton iterate and every line search's trial point)
intersect by ipctk's own test (has_intersections). About ten minutes.
"""
import argparse
import itertools
import time

import anisofem as af
from anisofem.io.output import publish, result_path
from anisofem.physics import self_contact
from anisofem.physics.contact import ContactTerm
from anisofem.studies.drops import MATERIAL, fall_steps, stacked

PAIRS = (("tee", "beam"), ("rod", "tee"), ("beam", "rod"))


class Watch:
    """Counts the points at which self-contact's energy is evaluated, and those of them whose
    surface intersects itself (ipctk.has_intersections)."""

    def __init__(self):
        self.points = self.intersecting = 0
        self._energy = self_contact.SelfContact.energy

    def __enter__(self):
        watch = self

        def energy(contact, x, grad=None):
            watch.points += 1
            watch.intersecting += bool(contact.ipctk.has_intersections(
                contact.mesh, contact.vertices(x)))
            return watch._energy(contact, x, grad)
        self_contact.SelfContact.energy = energy
        return self

    def __exit__(self, *exc):
        self_contact.SelfContact.energy = self._energy


def rows():
    out = []
    for (lower, upper), g, dt in itertools.product(PAIRS, (1, 10, 100), (0.005, 0.02, 0.05)):
        mesh, _ = stacked(lower, upper)
        scene = af.Scene(mesh, MATERIAL, gravity=(0, 0, -9.81 * g), contact=af.Contact(
            [af.Plane(name="ground")], friction=0.3, self_contact=True))
        term = ContactTerm(scene)
        t0 = time.perf_counter()
        with Watch() as watch:
            roll = af.simulate(scene, fall_steps(9.81 * g, dt), dt=dt, warn=False)
        out.append({
            "lower": lower, "upper": upper, "g": g, "dt": dt, "steps": len(roll.steps),
            "converged": roll.converged,
            "most_newton": max(s.newton.iterations for s in roll.steps),
            "all_newton": sum(s.newton.iterations for s in roll.steps),
            "nearest_each_other_um": 1e6 * min(term.itself.nearest(s.x) for s in roll.steps),
            "nearest_ground_um": 1e6 * min(float(term.distances(s.x).min())
                                           for s in roll.steps),
            "dhat_um": 1e6 * term.dhat,
            "inverted": max(s.newton.inversion.inverted for s in roll.steps),
            "points": watch.points, "intersecting": watch.intersecting,
            "seconds": time.perf_counter() - t0})
    return out


def _print(report):
    print(f"{'dropped onto':<14} {'g':>4} {'dt s':>6} {'steps':>5} {'Newton most/all':>15} "
          f"{'nearest um':>10} {'ground um':>9} {'dhat um':>7} {'inverted':>8} "
          f"{'points':>7} {'intersecting':>12} converged")
    for r in report["stacked"]:
        print(f"{r['upper'] + ' / ' + r['lower']:<14} {r['g']:4d} {r['dt']:6.3f} "
              f"{r['steps']:5d} {r['most_newton']:7d}/{r['all_newton']:<7d} "
              f"{r['nearest_each_other_um']:10.1f} {r['nearest_ground_um']:9.1f} "
              f"{r['dhat_um']:7.1f} {r['inverted']:8d} {r['points']:7d} "
              f"{r['intersecting']:12d} {r['converged']}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", default=result_path("stacked_drops.json"))
    args = parser.parse_args()
    publish({"stacked": rows()}, _print, args.json)


if __name__ == "__main__":
    main()
