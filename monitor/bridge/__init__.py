"""The sensor bridge (``buoymon bridge``): instruments on serial ports, sockets and logger
files in, blocks of samples out on ``buoy/<id>/sensor/<stream>`` through
:class:`monitor.sensors.SensorPublisher` (cache, miss detection, liveliness).

Data path per ``[[source]]``: transport (bytes -> lines, reconnecting) -> format (a line ->
one timed sample, or a counted rejection) -> blocks of ``block_s`` with strictly increasing
time -> publisher. Modules: :mod:`.config`, :mod:`.transports`, :mod:`.formats`,
:mod:`.runner`.
"""
