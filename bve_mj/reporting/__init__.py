"""What results become: tables, plots, videos and the results page (written whole or not at
all through :mod:`bve_mj.atomic`).

- :mod:`.campaign_report`: a campaign's CSV, summary JSON and plots.
- :mod:`.plots`: figures (matplotlib, imported only when a figure is drawn).
- :mod:`.video`: the approach video of an episode.
- :mod:`.results_page`: ``docs/results.md`` from the results campaigns.
"""
