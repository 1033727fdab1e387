"""The simulated cell: scenarios, object sets, the one plant assembly, the station Diagram, grasp trials."""
