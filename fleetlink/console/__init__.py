"""The fleetlink web console: a live view of the fleet and its mappings, and the place to change them.

Served by each edge agent (its own site, under ``/console/`` of its admin HTTP server) and by
the uplink (every site, through the Zenoh admin space ``fleetlink/<site>/admin/**``, on the
port of its ``console`` section). Server-rendered pages (Jinja2) with one small script that
polls JSON; every asset ships in the package (no network at run time).

- pure core: ``forms`` (form <-> request body, errors -> fields), ``rates`` (counter deltas ->
  rates), ``graph`` (robots -> topics -> mappings -> Kafka), ``views`` (a site's page data),
  ``status`` (an edge's spool/WAN/topic counters), ``delivery`` (every uplink's Kafka figures added up),
  ``envelope`` (the admin space's answers), ``auth`` (token, session cookie);
- sources: ``local.LocalSite`` (in process), ``remote.ZenohSites`` (over Zenoh);
- adapters: ``app.create_console_app`` (FastAPI), ``edge.EdgeConsole``, ``uplink.UplinkConsole``.

The console sits above the edge, the uplink and the repeater: it is served *by* their processes
as an extension the command line attaches (``edge.console_extension``, ``uplink.uplink_console``);
its config section lives in ``fleetlink.common.console_config`` so config files can name it.
See docs/console.md.
"""
