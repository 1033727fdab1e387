"""Motion planning for a grasp: IK, collision-free transit (OMPL), timing; typed failure reasons."""
