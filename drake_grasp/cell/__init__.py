"""The robot cell's runtime: the executive, failure memory, the episode, the cell diagram, detection."""
