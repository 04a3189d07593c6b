"""``python -m agvsim`` runs the ``agvsim`` command line."""

from agvsim.cli import app

if __name__ == "__main__":
    app(prog_name="agvsim")
