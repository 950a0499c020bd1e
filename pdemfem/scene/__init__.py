"""Scene files: the validated model (schema), loading (loader) and derived quantities (derived)."""
from pdemfem.scene.loader import load_scene, output_directory, resolve_path, scene_hash
from pdemfem.scene.schema import Scene

__all__ = ["Scene", "load_scene", "output_directory", "resolve_path", "scene_hash"]
