"""guide: learned autonomous exploration with global graph inference (GUIDE, Che et al.)."""

__version__ = "0.1.0"

try:  # the Gymnasium environment (pipeline/envs/, docs/environment.md), registered by name: nothing heavy loads here
    from gymnasium.envs.registration import register as _register
    from gymnasium.envs.registration import registry as _registry
except ImportError:  # pragma: no cover - gymnasium is a dependency; without it only the environment is missing
    pass
else:
    if "guide/Explore-v0" not in _registry:
        _register(id="guide/Explore-v0", entry_point="pipeline.envs.explore_env:ExploreEnv")
