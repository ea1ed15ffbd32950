"""The soft body in MuJoCo: the engine plugin "anisofem.soft" (export/c/mujoco_plugin.c over
the C runtime), built with the system C compiler against the installed `mujoco` wheel's
headers and library, and the MJCF that places a model file on a body.

    import mujoco
    from export import mujoco as soft
    soft.load_plugin()                          # builds it on first use, then registers it
    model = mujoco.MjModel.from_xml_string(soft.mjcf("models/finger"))
    data = mujoco.MjData(model)
    mujoco.mj_step(model, data)

    python -m export mujoco models/finger [--body hand] [--substeps 1] [--timestep 0.01]
"""
import os
from xml.sax.saxutils import quoteattr

from . import native

PLUGIN = os.path.join(native.FOLDER, "mujoco_plugin.c")
#: The plugin's name in MJCF (<plugin plugin="...">).
NAME = "anisofem.soft"
#: An instance's plugin state (mjData.plugin_state from model.plugin_stateadr): the time its
#: soft state is at, its last step's length, the soft body's pull on its carrier (a force, N,
#: its moment about the world's origin, N m), its carrier's place and velocity at the last
#: step's start, the obstacles' impulse over it; from HEADER on the runtime's state
#: (af_state_size), then 6 per obstacle (export/c/mujoco_plugin.c says what each holds).
HEADER = 20
#: Where in it the obstacles' impulse on the soft body over its last step is (3, N s, in the
#: model file's axes), then its moment (3).
TOUCHED = 14
_LOADED = {}


def mujoco_module():
    """The mujoco module, or ImportError saying how to install it."""
    try:
        import mujoco
    except ImportError:
        raise ImportError("the MuJoCo plugin needs MuJoCo: pip install mujoco (or pip install "
                          "anisofem[mujoco])") from None
    return mujoco


def build_plugin(folder=None):
    """Compile the plugin and the C runtime into folder/libanisofem_mujoco.so against the
    installed mujoco package (its include/ and libmujoco), unless it is there for these
    sources and that package; returns its path. folder: by default a cache folder
    ($ANISOFEM_CACHE, else ~/.cache/anisofem). ImportError without mujoco; RuntimeError without
    a C compiler or where it fails."""
    mujoco = mujoco_module()
    home = os.path.dirname(os.path.abspath(mujoco.__file__))
    include = os.path.join(home, "include")
    libraries = sorted(f for f in os.listdir(home) if f.startswith("libmujoco.so"))
    if not os.path.isdir(include) or not libraries:
        raise RuntimeError(f"the mujoco package in {home} (mujoco {mujoco.__version__}) has no "
                           f"include/ folder or libmujoco.so to build the plugin against")
    extra = [f"-I{include}", f"-I{native.FOLDER}", os.path.join(home, libraries[0]),
             f"-Wl,-rpath,{home}"]
    return native.compile_library("libanisofem_mujoco.so", (PLUGIN,) + native.SOURCES,
                                  native.HEADERS, extra, folder, prefix="mujoco")


def load_plugin(folder=None):
    """Build the plugin (build_plugin) and register it with MuJoCo, once per process; returns
    the library's path."""
    path = build_plugin(folder)
    if path not in _LOADED:
        mujoco_module().mj_loadPluginLibrary(path)
        _LOADED[path] = True
    return path


def mjcf(file, body="soft", substeps=1, pos=(0.0, 0.0, 0.0), name="soft", world="",
         timestep=None):
    """An MJCF model that places the model file `file` (path without extension) on a body
    named `body` at pos (3,), m, fixed to the world: its <extension> declares the instance
    `name` with its file, substeps and soft time step (timestep, s; None: MuJoCo's), the body
    names it. world: more MJCF for the worldbody (other bodies, lights, a floor)."""
    if not isinstance(substeps, int) or substeps < 1:
        raise ValueError(f"substeps: expected a whole number >= 1, got {substeps!r}")
    if timestep is not None and not (isinstance(timestep, (int, float)) and timestep > 0):
        raise ValueError(f"timestep: expected a time step > 0 s, got {timestep!r}")
    step = ("" if timestep is None else
            f'\n        <config key="timestep" value="{float(timestep):.17g}"/>')
    where = " ".join(f"{float(v):.17g}" for v in pos)
    return f"""<mujoco model={quoteattr(name)}>
  <extension>
    <plugin plugin="{NAME}">
      <instance name={quoteattr(name)}>
        <config key="file" value={quoteattr(os.fspath(file))}/>
        <config key="substeps" value="{substeps}"/>{step}
      </instance>
    </plugin>
  </extension>
  <worldbody>
    <body name={quoteattr(body)} pos="{where}">
      <plugin instance={quoteattr(name)}/>
    </body>{world}
  </worldbody>
</mujoco>
"""
