"""The ship-in-ice case of the paper (section 3): the B-063 hull, the brash-ice channel, the scene presets.

Public API::

    from iceresist.ship import HullGeometry, b063_hull, channel_layout, ChannelLayout
"""

from iceresist.ship.channel import ChannelLayout, channel_layout
from iceresist.ship.hull import HullGeometry, b063_hull

__all__ = ["HullGeometry", "b063_hull", "ChannelLayout", "channel_layout"]
