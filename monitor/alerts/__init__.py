"""Alerting: rules evaluated on sensor-time ticks, alert records, delivery and the CLI.

* :mod:`~monitor.alerts.config` validates the ``[alerts]`` TOML section;
* :mod:`~monitor.alerts.rules` has one class per rule kind;
* :mod:`~monitor.alerts.engine` (:class:`AlertEngine`) turns each
  :class:`monitor.events.Observation` into alert transitions and re-sends;
* :mod:`~monitor.alerts.records` defines :class:`AlertRecord` and the Alertmanager JSON;
* :mod:`~monitor.alerts.delivery` publishes on Zenoh and feeds webhook/e-mail through
  :mod:`~monitor.alerts.outbox`;
* :mod:`~monitor.alerts.cmd_alerts` is ``buoymon alerts list|ack|reset``.
"""
