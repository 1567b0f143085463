"""``tactile view``: the skin in a browser, live from the graph or from a bag (docs/view.md).

:mod:`.model` (the page's data, no ROS), :mod:`.server` (the page and its
event stream, standard library), :mod:`.live` (rclpy: the graph's contacts
and predictions), :mod:`.bag` (a bag played through the core, no ROS),
:mod:`.snapshot` (a PNG with matplotlib).
"""
