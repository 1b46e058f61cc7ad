"""Tests of ``splineplan route``: output, picture, and one-line errors."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from conftest import NETS

from splineplan.cli import main

CITY = str(NETS / "city.net.xml")


def test_route_prints_edges_and_length(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["route", CITY, "SWA0", "G1G2"]) == 0
    out = capsys.readouterr().out
    assert "bridge_east" in out and "length:" in out and " m" in out


def test_route_json_and_plot(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    png = tmp_path / "route.png"
    assert main(["route", CITY, "A1B1", "C2C3", "--vclass", "bus", "--weight", "time",
                 "--json", "--plot", str(png), "--start-pos", "5"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["edges"][0] == "A1B1" and data["edges"][-1] == "C2C3"
    assert data["vclass"] == "bus" and data["weight"] == "time" and data["length"] > 0
    assert png.stat().st_size > 10_000
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize(("args", "needle"), [
    (["route", "missing.net.xml", "a", "b"], "missing.net.xml"),
    (["route", str(NETS / "city.edg.xml"), "a", "b"], "city.edg.xml"),
    (["route", CITY, "nowhere", "G1G2"], "'nowhere'"),
    (["route", CITY, "SWA0", "G1G2", "--vclass", "car"], "'car'"),
    (["route", CITY, "SWA0", "G1G2", "--avoid", "bridge_east"], "bridge_east"),
    (["route", CITY, "SWA0", "bus_B1C2"], "bus_B1C2"),
    # an edge id with a leading minus is an edge id, not an option
    (["route", CITY, "-SWA0", "G1G2"], "'-SWA0'"),
])
def test_route_errors_are_one_line(args: list[str], needle: str,
                                   capsys: pytest.CaptureFixture[str]) -> None:
    assert main(args) != 0
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0] and "error" in lines[0]
    assert captured.out == ""


@pytest.mark.parametrize("args", [
    ["route", CITY, "SWA0", "G1G2", "--weight", "fuel"],
    ["route", CITY, "SWA0"],
    ["route", CITY, "SWA0", "G1G2", "--start-pos", "x"],
    ["route", CITY, "SWA0", "G1G2", "--start-pos", "-3"],
])
def test_argument_errors_are_one_line(args: list[str],
                                      capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main(args)
    assert info.value.code != 0
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "error" in lines[0]


def test_edge_ids_with_a_leading_minus(monaco_net: Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    """SUMO names the reverse direction of an edge with a minus (-1511#1): the CLI takes
    such ids as edges, before or after the options, without ``--``."""
    for args in (["route", str(monaco_net), "-1511#1", "-2951#2", "--json"],
                 ["route", "--json", str(monaco_net), "-1511#1", "-2951#2"]):
        assert main(args) == 0
        data = json.loads(capsys.readouterr().out)
        assert data["edges"][0] == "-1511#1" and data["edges"][-1] == "-2951#2"
