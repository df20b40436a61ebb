"""The tentacle: files, chain, statics at selectable fidelity (pure, no rclpy)."""
