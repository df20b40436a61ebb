"""The planner's input error: a scene, path or tentacle it cannot plan for."""


class PlanInputError(ValueError):
    """A scene or path file is unusable; the message names the file and the key or point."""
