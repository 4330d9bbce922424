"""The shipped figure's contact sites and feet, read from models/humanoid39.xml (`solver.figure.shipped_figure`),
for tests that build site arrays or contacts by hand; the library itself reads them from each model's figure."""
from solver.figure import shipped_figure

#: the shipped figure's contact sites, foot by foot (`Figure.contact_sites`)
SITES: tuple[str, ...] = shipped_figure().contact_sites
#: the shipped figure's feet {side: (heel, toe)} (`Figure.feet`)
FEET: dict[str, tuple[str, str]] = dict(shipped_figure().feet)
