"""What results become: tables, plots, videos, the results page, and atomic writes.

- :mod:`.atomic`: files written whole or not at all.
- :mod:`.campaign_report`: a campaign's CSV, summary JSON and plots.
- :mod:`.plots`: figures (matplotlib, imported only when a figure is drawn).
- :mod:`.video`: the approach video of an episode.
- :mod:`.results_page`: ``docs/results.md`` from the results campaigns.
"""
