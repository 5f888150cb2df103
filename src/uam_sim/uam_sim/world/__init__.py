"""The world a run flies in: demand (requests), the fleet's kinematics, the disturbances, the
conformance of what flew to its plan, and what a run's flights measure."""
