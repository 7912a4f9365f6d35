"""Reports: the terminal table and the Markdown summary of test outcomes (``outcome_report``),
their HTML report (``outcome_page``) and metric plot (``metric_plot``) on the shared page shell
(``html_page``), the HTML page of an experiment folder (``experiment_page``, with
``experiment_folder``, ``experiment_frames`` and ``experiment_results``), contact sheets, and the
one formatter of metrics and trial lines (``formatting``, on ``pytest_sal.engine.outcomes.quantity``)."""

__all__: list[str] = []
