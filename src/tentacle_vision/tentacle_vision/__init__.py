"""Image pipeline, camera source and tentacle tracker."""
