"""The solvers of the physics' potential: Newton and the faster methods of the ladder
(`methods`), the linear solvers and multigrid under them, load continuation, the stability
check at an answer, and `solve` / `simulate` / `step` (statics and backward Euler). Import the
physics, never a module above them."""
