"""The simulated world: scenarios, object sets and generators, the station Diagram, grasp trials, sleeping
objects, depth noise."""
