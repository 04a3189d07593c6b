"""A controller used by python_controller_name.yaml (which asks for a misspelt name)."""


def wander(obs):
    """Drive slowly forward: (vx m/s, vy m/s, omega rad/s)."""
    return (0.2, 0.0, 0.0)
