"""Reports: the terminal table, the Markdown summary, the HTML report of test outcomes, the HTML
page of an experiment folder, contact sheets, and the one formatter of numbers and intervals."""

__all__: list[str] = []
