"""Design studies: study files, equilibria in batch, results tables (pure, no rclpy)."""
