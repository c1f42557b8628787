"""Placeholder (being written)."""
HELP = 'placeholder'
EXAMPLE = ''


def add_arguments(parser):
    pass


def run(args):
    raise NotImplementedError
