"""``lightcurve reproduction``: write docs/reproduction.md from study outputs."""

from __future__ import annotations

from ._args import add_command, add_output, report_written

__all__ = ["register"]


def _cmd_reproduction(args) -> int:
    """Read the summary.json of finished studies (lightcurve compare -o DIR) and write, per source
    document, every claim we can test with our number, the document's and agrees / disagrees /
    not testable (Bernard 2021: Fig. 9.4 and B.1-B.4 cell by cell, the seven conclusions of sec.
    9.4, the spikes of the uncontrolled fast-spinning curves of sec. 9.4.5, the particle filter of
    Fig. 9.5-9.7, the reflection models of ch. 10).
    """
    from ..studies.reproduction import (bernard_section, css_section, load_summaries,
                                        write_reproduction)

    dirs = list(args.study or [])
    # every named folder must hold a study summary: checked before anything is written
    sums = load_summaries(dirs, strict=True)
    sections = [bernard_section(summaries=sums, reflection_kf_json=args.reflection_kf,
                                spikes_json=args.spikes),
                css_section(list(args.css or []), timing=args.css_timing,
                            tables4=args.css_tables4, sun_models=args.css_sun_models,
                            table44=args.css_table44, faults=list(args.css_faults or []),
                            vmm=args.css_vmm)]
    write_reproduction(args.output, sections, only=args.only)
    n = len(sums)
    n_css = len(args.css or [])
    return report_written(args.output, detail=f" ({n} Bernard and {n_css} CSS study output(s) "
                          "read)")


def register(sub) -> None:
    from ..studies.reproduction import SECTIONS

    p = add_command(
        sub, "reproduction", _cmd_reproduction,
        help="write docs/reproduction.md: every testable claim of the source documents, ours "
        "vs theirs")
    p.add_argument("--study", action="extend", nargs="+", metavar="DIR",
                   help="output folder(s) of 'lightcurve compare' (the Bernard studies, each "
                   "identified by its study name; repeatable, several per option allowed)")
    p.add_argument("--css", action="extend", nargs="+", metavar="DIR",
                   help="output folder(s) of 'lightcurve css study' (O'Keefe, DiGregorio; "
                   "repeatable, several per option allowed)")
    p.add_argument("--css-timing", default=None, metavar="FILE",
                   help="output of python benchmarks/css.py (O'Keefe Table 3.1)")
    p.add_argument("--css-tables4", default=None, metavar="FILE",
                   help="output of python benchmarks/css_tables_4.py (O'Keefe Tables 4.1-4.3)")
    p.add_argument("--css-table44", default=None, metavar="FILE",
                   help="output of python benchmarks/css_table_4_4.py (O'Keefe Table 4.4)")
    p.add_argument("--css-faults", action="extend", nargs="+", metavar="FILE",
                   help="JSON of 'lightcurve css faults --experiment table5_1|table5_2 -o FILE' "
                   "(O'Keefe Tables 5.1-5.2; repeatable, several per option allowed)")
    p.add_argument("--css-sun-models", default=None, metavar="FILE",
                   help="JSON of 'lightcurve css sun-models --table -o FILE' (O'Keefe Table 4.5)")
    p.add_argument("--css-vmm", default=None, metavar="FILE",
                   help="JSON of 'lightcurve css vmm -o FILE' (DiGregorio's VMM vs SMM)")
    p.add_argument("--reflection-kf", action="extend", nargs="+", metavar="FILE",
                   help="the JSON line printed by benchmarks/reflection_kf.py (sec. 10.4/10.7/"
                   "10.8; one file per filter variant, e.g. --variant thesis and robust; "
                   "repeatable, several per option allowed)")
    p.add_argument("--spikes", default=None, metavar="FILE",
                   help="the JSON line of python benchmarks/bernard_spikes.py (sec. 9.4.5, Fig. "
                   "9.19: the specular spikes of the controlled and uncontrolled fast-spinning "
                   "truths)")
    p.add_argument("--only", choices=sorted(SECTIONS), default=None,
                   help="write this source document's section only and keep the other sections "
                   "as they stand in the existing output file (rerun one document's studies "
                   "alone)")
    add_output(p, what="file", default="docs/reproduction.md",
               help="Markdown file to write")
