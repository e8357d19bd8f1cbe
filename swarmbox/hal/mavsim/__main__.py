"""``python -m swarmbox.hal.mavsim``: one mavsim vehicle process (see :mod:`swarmbox.hal.mavsim.process`)."""

from swarmbox.hal.mavsim.process import main

if __name__ == "__main__":
    main()
