"""``python -m tg_intrinsic``: the ``tg-intrinsic`` command line."""
from tg_intrinsic.cli import entry_point

if __name__ == '__main__':
    entry_point()
