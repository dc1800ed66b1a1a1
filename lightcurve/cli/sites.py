"""``lightcurve sites``: the observing-site catalogue."""

from __future__ import annotations

from ._args import add_command, add_group, add_sites

__all__ = ["register"]


def _cmd_sites_list(args) -> int:
    from ..geometry.sites import load_sites

    sites = load_sites(args.sites)
    if not sites:
        print("no sites found")
        return 0
    print(f"{'id':<16} {'lat_deg':>10} {'lon_deg':>11} {'height_m':>9}  band  name")
    for sid in sorted(sites):
        s = sites[sid]
        print(f"{s.id:<16} {s.lat_deg:>10.4f} {s.lon_deg:>11.4f} {s.height_m:>9.1f}  "
              f"{s.band:<4}  {s.name}")
    return 0


def _cmd_sites_show(args) -> int:
    from ..geometry.sites import get_site

    print(get_site(args.id, args.sites).describe())
    return 0


def register(sub) -> None:
    _, ssub = add_group(
        sub, "sites", title="sites commands", metavar="SUBCOMMAND",
        help="list or show observing sites (observatories/*.toml)",
        description="The site catalog: the bundled observatories/ folder plus any folders "
        "given with --sites (later folders override earlier ones). Each site is one TOML "
        "file with id, name, lat_deg, lon_deg (WGS84), height_m and optional band and "
        "[horizon_mask].")
    pl = add_command(ssub, "list", _cmd_sites_list, help="list all known sites")
    add_sites(pl)
    ps = add_command(ssub, "show", _cmd_sites_show, help="show one site")
    ps.add_argument("id", help="site id, e.g. socorro")
    add_sites(ps)
