"""Inverse problems: adjoint derivatives of a static answer or a rollout (`sensitivity`),
identification from measured markers (`fit`), fiber layouts for a target (`design`), and the
bounded quasi-Newton driver they share (`lbfgsb`). Build on the physics and the solvers."""
