"""Awkward but common input: each gets a message that names the real cause, or is accepted as it should be."""
import numpy as np
import pytest

from bayes_disc.cli import main
from bayes_disc.observation.config_io import ConfigError, load_yaml
from bayes_disc.observation.markers import MarkerFileError, read_marker_csv

IDS = ("0", "1", "2")
GOOD = """flight,t,marker,x,y,z
f1,0.0,0,0.10,0.00,1.00
f1,0.0,1,-0.03,0.08,1.00
f1,0.0,2,-0.07,-0.08,1.00
f1,0.00833,0,0.21,0.00,1.01
f1,0.00833,1,0.08,0.08,1.01
f1,0.00833,2,0.04,-0.08,1.01
"""


def _bytes(tmp_path, data: bytes, name="m.csv"):
    p = tmp_path / name
    p.write_bytes(data)
    return p


def _same_table(a, b):
    assert a.flights == b.flights
    np.testing.assert_array_equal(a.t, b.t)
    np.testing.assert_array_equal(a.marker, b.marker)
    np.testing.assert_array_equal(a.xyz, b.xyz)
    np.testing.assert_array_equal(a.lines, b.lines)


def test_byte_order_mark_and_crlf_read_like_plain_text(tmp_path):
    plain = read_marker_csv(_bytes(tmp_path, GOOD.encode(), "plain.csv"), IDS)
    bom = read_marker_csv(_bytes(tmp_path, b"\xef\xbb\xbf" + GOOD.encode(), "bom.csv"), IDS)
    crlf = read_marker_csv(_bytes(tmp_path, GOOD.replace("\n", "\r\n").encode(), "crlf.csv"), IDS)
    both = read_marker_csv(_bytes(tmp_path, b"\xef\xbb\xbf" + GOOD.replace("\n", "\r\n").encode(), "both.csv"), IDS)
    for other in (bom, crlf, both):
        _same_table(plain, other)


def test_binary_file_is_named(tmp_path):
    p = _bytes(tmp_path, GOOD.encode()[:40] + b"\x00\x01\x02\xff" * 10)
    with pytest.raises(MarkerFileError) as err:
        read_marker_csv(p, IDS)
    assert str(err.value).startswith(f"{p}:2:") and "binary file" in str(err.value), err.value


def test_non_utf8_file_names_byte_and_line(tmp_path):
    latin1 = GOOD.replace("f1,0.00833,1", "fé,0.00833,1").encode("latin-1")
    p = _bytes(tmp_path, latin1)
    with pytest.raises(MarkerFileError) as err:
        read_marker_csv(p, IDS)
    assert str(err.value) == f"{p}:6: not a UTF-8 text file (byte 0xe9); save it as UTF-8"


def test_semicolons_with_decimal_commas_are_named(tmp_path):
    text = GOOD.replace(",", ";").replace("0.", "0,").replace("1.", "1,")
    p = _bytes(tmp_path, text.encode())
    with pytest.raises(MarkerFileError) as err:
        read_marker_csv(p, IDS)
    msg = str(err.value)
    assert msg.startswith(f"{p}:1:") and "separated by ';' with decimal commas" in msg, msg
    assert "comma-separated with decimal points" in msg


def test_semicolons_without_decimal_commas_and_tabs_are_named(tmp_path):
    with pytest.raises(MarkerFileError, match="fields separated by ';': export as comma-separated"):
        read_marker_csv(_bytes(tmp_path, GOOD.replace(",", ";").encode()), IDS)
    with pytest.raises(MarkerFileError, match="fields separated by tabs"):
        read_marker_csv(_bytes(tmp_path, GOOD.replace(",", "\t").encode(), "tab.csv"), IDS)


def test_folder_given_as_marker_file_is_named(tmp_path):
    with pytest.raises(MarkerFileError, match="is a folder, not a file"):
        read_marker_csv(tmp_path, IDS)


def test_folder_given_as_config_is_named(tmp_path, capsys):
    with pytest.raises(ConfigError, match=r"is a folder, not a file \(expected a YAML config\)"):
        load_yaml(tmp_path)
    assert main(["sample", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "is a folder" in err, err


def test_config_with_bom_and_crlf_reads_and_latin1_config_is_named(tmp_path):
    p = _bytes(tmp_path, b"\xef\xbb\xbfname: demo\r\nprior: weak\r\n", "c.yaml")
    assert load_yaml(p) == {"name": "demo", "prior": "weak"}
    q = _bytes(tmp_path, "name: démo\n".encode("latin-1"), "d.yaml")
    with pytest.raises(ConfigError, match=r"line 1: not a UTF-8 text file \(byte 0xe9\)"):
        load_yaml(q)
