"""A live web page of a run: the loop as it goes, the controller's plan, its limits and
status, and the operator's switches (``cosim run --hmi``); the same page after the fact
(``cosim view``), and a campaign's runs (``cosim campaign --hmi``).

:mod:`cosim.hmi.feed` is what the page reads (during a run, the run's watcher in its loop),
:mod:`cosim.hmi.actions` what an operator may do (one checked request each, audited),
:mod:`cosim.hmi.panels` and :mod:`cosim.hmi.page` the page itself (Bokeh),
:mod:`cosim.hmi.server` the Bokeh server in a thread with its login
(:mod:`cosim.hmi.users`), :mod:`cosim.hmi.replay` a finished run read back,
:mod:`cosim.hmi.campaign_page` a campaign's list and :mod:`cosim.hmi.serving` how each is
served. Bokeh is imported only when a page is served.
"""
