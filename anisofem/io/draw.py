"""Pictures of deformed bodies (matplotlib): the boundary of a mesh at positions x, shaded and
colored by displacement, over its ghosted rest shape. The examples draw with it."""
import matplotlib
import numpy as np


def deformed_surface(ax, mesh, x, norm, ghost=True, cmap="viridis"):
    """Draw the boundary of `mesh` at positions x (n, 3), m, on a 3D axes: faces colored by
    their mean displacement in mm through `norm` (a matplotlib Normalize, mm) and shaded by a
    light from the upper left; with ghost, the rest shape faintly behind."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection
    faces = mesh.boundary_faces
    if ghost:
        ax.add_collection3d(Poly3DCollection(mesh.vertices[faces],
                                             facecolor=(0.6, 0.6, 0.6, 0.08),
                                             edgecolor=(0.5, 0.5, 0.5, 0.15), lw=0.3))
    u = 1e3 * np.linalg.norm(x - mesh.vertices, axis=1)[faces].mean(axis=1)
    tri = x[faces]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    light = matplotlib.colors.LightSource(azdeg=315, altdeg=45)
    shade = light.shade_normals(normals / np.linalg.norm(normals, axis=1, keepdims=True))
    colors = matplotlib.colormaps[cmap](norm(u))
    colors[:, :3] *= (0.45 + 0.55 * shade)[:, None]
    ax.add_collection3d(Poly3DCollection(tri, facecolors=colors, edgecolor="none"))
