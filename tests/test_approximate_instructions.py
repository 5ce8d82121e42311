"""scripts/approximate_instructions.py: its table of the instructions each CPU vendor rounds its own way, from a
report of the kind its gdb script writes, and its refusal without gdb."""

import pytest

import scripts


@pytest.fixture(scope="module")
def probe():
    return scripts.load("approximate_instructions")


def test_the_table_puts_the_libraries_whose_instructions_ran_first_and_counts_each_site_once(probe):
    report = {
        "found": {"/x/cv2.abi3.so": 681, "/y/libembree4-1.so.4": 3560, "/z/libm.so.6": 40},
        "ran": [
            ["/y/libembree4-1.so.4", "rcpps", "0x99215"],
            ["/y/libembree4-1.so.4", "rcpps", "0x9e8a4"],
            ["/y/libembree4-1.so.4", "rsqrtss", "0x91321"],
        ],
        "exit_code": 0,
    }
    rows = probe.table(report).splitlines()[2:]
    assert rows[0] == "| libembree4-1.so.4 | 3560 | 3 | rcpps (2), rsqrtss (1) |"
    assert rows[1:] == ["| cv2.abi3.so | 681 | 0 | - |", "| libm.so.6 | 40 | 0 | - |"]


def test_the_mnemonics_name_the_approximate_forms_only(probe):
    import re

    legacy = re.compile(rf"^({probe.LEGACY})$")
    assert all(legacy.match(m) for m in ("rcpps", "rsqrtss", "fsin", "fyl2xp1"))
    # Exactly specified instructions that merely share a prefix are not watched.
    assert not any(legacy.match(m) for m in ("sqrtps", "divps", "rcp", "fsqrt", "fsubp"))
    assert re.fullmatch(probe.VEX, "vrcp14ps") and not re.fullmatch(probe.VEX, "vsqrtps")


def test_without_gdb_it_says_so_and_exits_non_zero(probe, monkeypatch, capsys):
    monkeypatch.setattr(probe.shutil, "which", lambda name: None)
    assert probe.main([]) == 1
    assert "needs gdb" in capsys.readouterr().err
