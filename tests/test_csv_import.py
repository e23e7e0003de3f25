"""CSV import: exact times, every bad-row case with its line number, header errors, the CLI."""

from __future__ import annotations

import numpy as np
import pytest

from monitor.cli import main
from replay.csv_import import parse_iso_ns, read_csv
from replay.reader import LogReader

Y2000 = 946_684_800 * 10**9


def _csv(tmp_path, text, name="b7.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_every_bad_row_is_reported_with_line_and_reason(tmp_path):
    p = _csv(tmp_path, "\n".join([
        "time_s,tension_N",      # 1
        "0,1000",                # 2 ok
        "0.05,1010",             # 3 ok
        "0.05,1020",             # 4 duplicate time
        "0.1,abc",               # 5 unparsable
        "",                      # 6 blank
        "0.2,nan",               # 7 NaN
        "0.15,1,2",              # 8 wrong column count
        "0.3,",                  # 9 empty cell
        "0.25,1e999",            # 10 infinite
        "x.5,1",                 # 11 bad time
        "0.2,999",               # 12 ok (0.2 > 0.05)
        "0.1,999",               # 13 backwards
        "0.3,1100",              # 14 ok
    ]) + "\n")
    d = read_csv(p)
    got = [(b.line, b.reason.split(":")[0]) for b in d.bad_rows]
    assert got == [(4, "duplicate time"), (5, "unparsable number in column tension_N"),
                   (7, "NaN in column tension_N"), (8, "wrong column count"),
                   (9, "empty cell in column tension_N"),
                   (10, "infinite value in column tension_N"),
                   (11, "bad time_s 'x.5'"), (13, "time going backwards")]
    assert (d.rows_read, d.rows_accepted, d.rows_skipped, d.blank_lines) == (12, 4, 8, 1)
    t, v = d.sensors["tension"]
    assert t.tolist() == [Y2000, Y2000 + 50_000_000, Y2000 + 200_000_000, Y2000 + 300_000_000]
    assert v.tolist() == [[1000.0, 1010.0, 999.0, 1100.0]]


def test_times_are_exact_to_the_nanosecond(tmp_path):
    p = _csv(tmp_path, "time,tension_N,accel_x_mps2,accel_y_mps2,accel_z_mps2\n"
                       "2024-03-01T12:00:00Z,1,0,0,9.81\n"
                       "2024-03-01T12:00:00.000000001Z,2,0,0,9.8\n"
                       "2024-03-01T14:00:00.5+02:00,3,0.5,0,1\n"
                       "2024-03-01 12:00:01.25,4,0,-0.5,0\n")
    d = read_csv(p)
    base = 1_709_294_400 * 10**9  # 2024-03-01T12:00:00Z
    t, v = d.sensors["imu"]
    assert t.tolist() == [base, base + 1, base + 500_000_000, base + 1_250_000_000]
    assert v[2].tolist() == [9.81, 9.8, 1.0, 0.0]
    assert d.sensors["tension"][1].tolist() == [[1.0, 2.0, 3.0, 4.0]]
    assert parse_iso_ns("1970-01-01T00:00:01.1Z") == 1_100_000_000
    with pytest.raises(ValueError, match="more than 9 fractional digits"):
        parse_iso_ns("2024-03-01T12:00:00.0000000001Z")
    p = _csv(tmp_path, "time_s,tension_N\n1.000000001,5\n1e1,6\n", "rel.csv")
    t = read_csv(p, start="1970-01-01T00:00:00Z").sensors["tension"][0]
    assert t.tolist() == [10**9 + 1, 10 * 10**9]


@pytest.mark.parametrize("header, message", [
    ("tension_N,heave_m", "exactly one time column"),
    ("time,time_s,tension_N", "exactly one time column"),
    ("time_s", "no channel column"),
    ("time_s,tension_kN", r"'tension_kN' \(column 2\): wrong unit, expected 'tension_N'"),
    ("time_s,temperature_C", "expected <channel>_<unit>"),
    ("time_s,heave_m,surge_m", r"\['sway_m'\] missing: motion needs all"),
    ("time_s,tension_N,tension_N", "duplicate columns"),
])
def test_header_errors_name_the_column(tmp_path, header, message):
    with pytest.raises(ValueError, match=message):
        read_csv(_csv(tmp_path, header + "\n0,1,2\n"))


def test_cli_import_round_trip_keeps_irregular_sampling(tmp_path, capsys):
    rng = np.random.default_rng(4)
    t_s = np.cumsum(rng.uniform(0.01, 0.2, 300))
    tension = 5000 + 500 * np.sin(t_s)
    heave = np.cos(t_s)
    lines = ["time_s,tension_N,heave_m,surge_m,sway_m"]
    lines += [f"{a:.6f},{float(b)!r},{float(c)!r},0,0" for a, b, c in zip(t_s, tension, heave)]
    lines.insert(50, "12,oops,0,0,0")
    src = _csv(tmp_path, "\n".join(lines) + "\n")
    out = tmp_path / "out.mcap"
    assert main(["import", str(src), "-o", str(out), "--buoy-id", "vaps-1"]) == 0
    cap = capsys.readouterr()
    assert "line 51: unparsable number in column tension_N: 'oops'" in cap.err
    assert "rows read 301, accepted 300, skipped 1" in cap.out
    reader = LogReader(out, coalesce=False)
    blocks = [b for b in reader if b.sensor == "tension"]
    expected_t = Y2000 + np.round(t_s * 1e6).astype(np.int64) * 1000
    assert np.array_equal(np.concatenate([b.t_ns for b in blocks]), expected_t)
    # every sample within half a quantum (0.1 N by default) of the CSV's
    got = np.concatenate([b.fields["tension_N"] for b in blocks])
    assert np.all(np.abs(got - tension) <= 0.05) and np.any(np.abs(got - tension) > 0.04)
    # ~1 s blocks on the second grid
    assert len(blocks) == len(np.unique(expected_t // 10**9))
    assert {b.buoy_id for b in blocks} == {"vaps-1"} and reader.stats[0].messages == 2 * len(blocks)


def test_cli_import_quantum_option(tmp_path, capsys):
    """--quantum FIELD=Q: that field to Q (within Q/2 of the CSV), the others to the defaults."""
    rows = ["time_s,tension_N,heave_m,surge_m,sway_m"]
    rows += [f"{k * 0.1:.1f},{5000 + 7.3 * k!r},{0.0123 * k!r},0,0" for k in range(40)]
    src = _csv(tmp_path, "\n".join(rows) + "\n")
    out = tmp_path / "q.mcap"
    assert main(["import", str(src), "-o", str(out), "--quantum", "tension_N=2",
                 "--quantum", "heave_m=1e-4"]) == 0
    got = {b.sensor: b for b in LogReader(out)}
    tension = got["tension"].fields["tension_N"]
    assert np.array_equal(tension, np.round(tension / 2) * 2)
    assert np.all(np.abs(tension - (5000 + 7.3 * np.arange(40))) <= 1.0)
    assert np.all(np.abs(got["motion"].fields["heave_m"] - 0.0123 * np.arange(40)) <= 0.5e-4)
    capsys.readouterr()
    assert main(["import", str(src), "-o", str(out), "--quantum", "tension=2"]) == 2
    assert "--quantum 'tension=2': expected FIELD=Q" in capsys.readouterr().err


def test_cli_exit_codes(tmp_path, capsys):
    out = tmp_path / "o.mcap"
    assert main(["import", str(_csv(tmp_path, "time_s,tension_N\n0,x\n")), "-o", str(out)]) == 1
    assert "no valid rows" in capsys.readouterr().err and not out.exists()
    assert main(["import", str(_csv(tmp_path, "t,tension_N\n")), "-o", str(out)]) == 2
    assert "exactly one time column" in capsys.readouterr().err
    bad_name = _csv(tmp_path, "time_s,tension_N\n1,2\n", "bad id!.csv")
    assert main(["import", str(bad_name), "-o", str(out)]) == 2
    assert "--buoy-id" in capsys.readouterr().err


def test_only_plain_decimal_numbers_are_read(tmp_path):
    """Python would read "1_000" as 1000 and "٣" as 3: a CSV cell is a plain number or bad."""
    p = _csv(tmp_path, "time_s,tension_N\n0,1_000\n1,\u0663\n2,1.5e3\n3,+.5\n4_0,7\n5,-2.\n6,0x10\n")
    d = read_csv(p)
    assert [(b.line, b.reason) for b in d.bad_rows] == [
        (2, "unparsable number in column tension_N: '1_000'"),
        (3, "unparsable number in column tension_N: '\u0663'"),
        (6, "bad time_s '4_0': not a number"),
        (8, "unparsable number in column tension_N: '0x10'")]
    assert d.sensors["tension"][1].tolist() == [[1500.0, 0.5, -2.0]]


def test_cli_lists_the_first_bad_rows_and_counts_the_rest(tmp_path, capsys):
    rows = ["time_s,tension_N"] + [f"{k},{'x' if k % 2 else 1000 + k}" for k in range(300)]
    rows += ["400,nan", "401,nan"]
    p = _csv(tmp_path, "\n".join(rows) + "\n")
    out = tmp_path / "o.mcap"
    assert main(["import", str(p), "-o", str(out), "--buoy-id", "b1"]) == 0
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 101 and err[0].endswith("line 3: unparsable number in column tension_N: 'x'")
    assert err[-1].endswith("... and 52 more bad rows (50 unparsable number in column "
                            "tension_N, 2 NaN in column tension_N); --max-errors 0 lists them all")
    assert main(["import", str(p), "-o", str(out), "--buoy-id", "b1", "--max-errors", "0"]) == 0
    assert len(capsys.readouterr().err.splitlines()) == 152
