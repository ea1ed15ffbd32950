"""Files: meshes in and out (meshio, with Gmsh's physical groups; `meshes`), scene files
(TOML; `scenefile`), results written atomically (`output`) and pictures of deformed bodies
(`draw`, with matplotlib). Build on the physics."""
from .meshes import (read_mesh, read_surface, read_tagged_mesh, write_mesh, write_series,
                     write_tagged_mesh)

__all__ = ["read_mesh", "read_surface", "read_tagged_mesh", "write_mesh", "write_series",
           "write_tagged_mesh"]
