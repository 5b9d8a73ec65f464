"""The one error of the bag package, :class:`BagError` (docs/bags.md).

A bag or MCAP file that cannot be written, read or recovered, with a message that names the
file and what is wrong.
"""


class BagError(Exception):
    """A bag or MCAP file that cannot be written, read or recovered; the message names it."""
