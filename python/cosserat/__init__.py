"""Fast, accurate Cosserat rod simulation: guidewires, catheters, sutures, cables.

The package wraps the Rust library ``cosserat`` (CoRdE rods, the stiff scheme, mesh contacts,
GPU kernels). A simulation is built from a scene (a TOML file or string, the same format as the
``cosserat`` command's) and is then stepped and steered from Python::

    import cosserat
    sim = cosserat.Simulation.from_file("scenes/pendulum.toml", {"rod.elements": 100})
    sim.run(1000)                 # the GIL is released while stepping
    tip = sim.positions()[-1]     # NumPy arrays, shape (n + 1, 3)

:class:`Batch` holds copies of one scene (sharing its mesh), steps them in parallel and reads
and steers them as arrays with a leading copy axis: one simulation per copy on the CPU, one
simulation of all copies on the GPU (``layout=`` chooses).

Rods are addressed by index (``rod=0`` by default), ends as 0 (first point) and 1 (last point).
Errors are exceptions carrying the library's messages: :class:`SceneError` (a scene that
cannot be built; the message names the file, field and value), :class:`StepError` (a run that
diverged, naming the rod, element and step), :class:`ControlError` (a refused control call;
nothing was changed).

``cosserat.distributed`` runs parameter sweeps of a scene on a Ray cluster (``pip install
"cosserat[distributed]"``); it is not imported here.

``cosserat.bench`` is a solver for the cosseratbench rod benchmarks (``pip install
"cosserat[bench]"``; ``docs/benchmarks/cosseratbench.md``); it is not imported here.
"""

from ._cosserat import (
    Batch,
    ControlError,
    SceneError,
    Simulation,
    Snapshot,
    StepError,
    __version__,
)

__all__ = [
    "Batch",
    "ControlError",
    "SceneError",
    "Simulation",
    "Snapshot",
    "StepError",
    "__version__",
]
