"""The submission validator: folders and zips, every problem listed, members escaping the folder."""

from __future__ import annotations

import io
import pickle
import stat
import zipfile

import numpy as np
import pytest
from helpers import pfm_bytes, write_submission, zip_folder

from lfbench.cli import main
from lfbench.data.submission_check import BENCHMARK_SCENES, parse_size, validate_submission
from lfbench.utils.errors import DataError

SIZE = (16, 16)  # small maps keep the tests fast; --size / size= sets it


def _maps(scenes=BENCHMARK_SCENES, shape=SIZE, seed=0):
    rng = np.random.default_rng(seed)
    return {s: rng.uniform(-2, 2, shape).astype(np.float32) for s in scenes}


@pytest.fixture()
def good(tmp_path):
    return write_submission(tmp_path / "sub", _maps())


def _problems(report) -> list[str]:
    return [str(p) for p in report.problems]


def test_benchmark_scene_list():
    assert BENCHMARK_SCENES == ("backgammon", "dots", "pyramids", "stripes", "boxes", "cotton", "dino", "sideboard",
                                "bedroom", "bicycle", "herbs", "origami")


def test_valid_folder_and_zips(good, tmp_path):
    assert validate_submission(good, size=SIZE).ok
    assert validate_submission(zip_folder(good, tmp_path / "flat.zip"), size=SIZE).ok
    assert validate_submission(zip_folder(good, tmp_path / "nested.zip", prefix="mymethod/"), size=SIZE).ok


def test_default_size_is_512(good):
    report = validate_submission(good)
    assert len(report.problems) == 12
    assert all("map is 16x16, expected 512x512" in p for p in _problems(report))


def test_every_problem_is_listed_naming_the_file(good):
    (good / "disp_maps" / "dots.pfm").unlink()
    (good / "runtimes" / "dino.txt").unlink()
    (good / "disp_maps" / "boxes.pfm").write_bytes(b"Pf\n16 16\n-1\n" + b"\0" * 100)  # truncated
    (good / "disp_maps" / "cotton.pfm").write_bytes(b"not a pfm at all")
    (good / "disp_maps" / "herbs.pfm").write_bytes(pfm_bytes(np.zeros((16, 15), np.float32)))
    nan_map = np.zeros(SIZE, np.float32)
    nan_map[0, :3] = np.nan
    nan_map[1, 0] = -np.inf
    (good / "disp_maps" / "origami.pfm").write_bytes(pfm_bytes(nan_map, big_endian=True))
    (good / "disp_maps" / "bedroom.pfm").write_bytes(pfm_bytes(np.zeros((16, 16, 3), np.float32), ident=b"PF"))
    (good / "runtimes" / "stripes.txt").write_text("-1.0\n")
    (good / "runtimes" / "bicycle.txt").write_text("0\n")
    (good / "runtimes" / "sideboard.txt").write_text("fast\n")
    (good / "runtimes" / "pyramids.txt").write_text("1.0 2.0\n")
    (good / "runtimes" / "backgammon.txt").write_text("inf\n")
    (good / "notes.txt").write_text("hello")
    (good / "disp_maps" / "extra.pfm").write_bytes(pfm_bytes(np.zeros(SIZE, np.float32)))
    report = validate_submission(good, size=SIZE)
    got = _problems(report)
    d, r = good / "disp_maps", good / "runtimes"
    expected = [
        f"{d / 'dots.pfm'}: missing",
        f"{r / 'dino.txt'}: missing",
        f"{d / 'boxes.pfm'}: truncated PFM",
        f"{d / 'cotton.pfm'}: not a PFM file",
        f"{d / 'herbs.pfm'}: map is 15x16, expected 16x16",
        f"{d / 'origami.pfm'}: 4 non-finite values (3 NaN, 1 inf)",
        f"{d / 'bedroom.pfm'}: 3-channel PF map",
        f"{r / 'stripes.txt'}: runtime '-1.0' is not a positive decimal number",
        f"{r / 'bicycle.txt'}: runtime '0' must be a positive finite number of seconds",
        f"{r / 'sideboard.txt'}: runtime 'fast' is not a positive decimal number",
        f"{r / 'pyramids.txt'}: expected one number of seconds, found 2 values",
        f"{r / 'backgammon.txt'}: runtime 'inf' is not a positive decimal number",
        f"{good / 'notes.txt'}: unexpected file",
        f"{d / 'extra.pfm'}: unexpected file",
    ]
    for e in expected:
        assert any(g.startswith(e) for g in got), (e, got)
    assert len(got) == len(expected)
    assert all("\n" not in g for g in got)


def test_runtime_formats(tmp_path):
    ok = {"a": "1.5\n", "b": "  2 \n", "c": "1e-3", "d": ".5", "e": "+3.25\n"}
    sub = write_submission(tmp_path / "s", _maps(ok), ok)
    assert validate_submission(sub, scenes=list(ok), size=SIZE).ok
    bad = {"a": "", "b": "1_000", "c": "nan", "d": "1e999", "e": "0x10", "f": "1,5"}
    sub = write_submission(tmp_path / "t", _maps(bad), bad)
    assert len(validate_submission(sub, scenes=list(bad), size=SIZE).problems) == len(bad)
    (sub / "runtimes" / "a.txt").write_bytes(b"\xff\xfe1")
    assert "not UTF-8" in _problems(validate_submission(sub, scenes=["a"], size=SIZE))[0]


def test_scene_list_and_size_are_overridable(tmp_path):
    sub = write_submission(tmp_path / "s", _maps(["synth_0", "synth_1"], shape=(20, 30)))
    assert validate_submission(sub, scenes=["synth_0", "synth_1"], size=(20, 30)).ok
    report = validate_submission(sub, scenes=["synth_0"], size=(20, 30))
    assert sorted(p.message for p in report.problems) == ["unexpected file", "unexpected file"]
    assert parse_size("512") == (512, 512) and parse_size("30x20") == (20, 30)
    for text in ("0", "x", "12x", "-5"):
        with pytest.raises(DataError):
            parse_size(text)


def test_oversized_files_are_not_read(good):
    big = good / "disp_maps" / "dots.pfm"
    big.write_bytes(pfm_bytes(np.zeros((16, 16), np.float32)) + b"\0" * (1 << 20))
    (good / "runtimes" / "dots.txt").write_text("1" * 1000)
    got = _problems(validate_submission(good, size=SIZE))
    assert any(g.startswith(f"{big}: file too large") for g in got)
    assert any("runtimes/dots.txt: runtime file too large" in g for g in got)
    # a real-size 512x512 map checked against --size 16: its header says what is wrong
    big.write_bytes(pfm_bytes(np.zeros((512, 512), np.float32)))
    got = _problems(validate_submission(good, size=SIZE))
    assert f"{big}: map is 512x512, expected 16x16" in got


def test_symlinks_in_a_folder_are_refused(good, tmp_path):
    outside = tmp_path / "secret.pfm"
    outside.write_bytes(pfm_bytes(np.zeros(SIZE, np.float32)))
    (good / "disp_maps" / "dots.pfm").unlink()
    (good / "disp_maps" / "dots.pfm").symlink_to(outside)
    (good / "linked_dir").symlink_to(tmp_path)
    got = _problems(validate_submission(good, size=SIZE))
    assert f"{good / 'disp_maps' / 'dots.pfm'}: symbolic link (not allowed in a submission)" in got
    assert f"{good / 'linked_dir'}: symbolic link (not allowed in a submission)" in got


def _zip_with(good, tmp_path, *extra) -> str:
    return str(zip_folder(good, tmp_path / "sub.zip", extra=extra))


@pytest.mark.parametrize("member, fragment", [
    ("../evil.txt", "'..' in the path (escapes the submission folder)"),
    ("disp_maps/../../evil.pfm", "'..' in the path"),
    ("/etc/evil.txt", "absolute path"),
    ("C:/evil.txt", "absolute path"),
    ("disp_maps\\..\\..\\evil.txt", "backslashes"),
])
def test_zip_members_escaping_the_folder(good, tmp_path, member, fragment):
    zpath = _zip_with(good, tmp_path, (member, b"x"))
    got = _problems(validate_submission(zpath, size=SIZE))
    assert got == [f"{zpath}:{member}: {fragment}"] or (
        len(got) == 1 and got[0].startswith(f"{zpath}:{member}: ") and fragment in got[0]), got
    assert not (tmp_path / "evil.txt").exists() and not (tmp_path.parent / "evil.txt").exists()


def test_zip_symlink_member(good, tmp_path):
    info = zipfile.ZipInfo("disp_maps/link.pfm")
    info.create_system = 3
    info.external_attr = (stat.S_IFLNK | 0o777) << 16
    zpath = _zip_with(good, tmp_path, (info, b"/etc/passwd"))
    assert _problems(validate_submission(zpath, size=SIZE)) == [
        f"{zpath}:disp_maps/link.pfm: symbolic link (not allowed in a submission)"]


def test_zip_problems_are_found_in_memory(good, tmp_path):
    (good / "runtimes" / "dots.txt").write_text("-2")
    (good / "disp_maps" / "cotton.pfm").unlink()
    zpath = _zip_with(good, tmp_path, ("README.md", b"hi"), ("disp_maps/", b""))
    got = _problems(validate_submission(zpath, size=SIZE))
    assert sorted(got) == sorted([f"{zpath}:disp_maps/cotton.pfm: missing",
                                  f"{zpath}:runtimes/dots.txt: runtime '-2' is not a positive decimal number",
                                  f"{zpath}:README.md: unexpected file"])


def test_zip_with_duplicate_members_and_nested_folder(good, tmp_path):
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        for p in sorted(good.rglob("*")):
            if p.is_file():
                zf.write(p, "method/" + p.relative_to(good).as_posix())
        with pytest.warns(UserWarning):
            zf.writestr("method/runtimes/dots.txt", "2.0")
    (tmp_path / "dup.zip").write_bytes(buf.getvalue())
    got = _problems(validate_submission(tmp_path / "dup.zip", size=SIZE))
    assert got == [f"{tmp_path / 'dup.zip'}:method/runtimes/dots.txt: duplicate member name"]


def test_not_a_zip_and_missing_path(tmp_path):
    (tmp_path / "sub.zip").write_bytes(b"PK\x03\x04 broken")
    with pytest.raises(DataError, match="not a valid zip file"):
        validate_submission(tmp_path / "sub.zip")
    with pytest.raises(DataError, match="submission not found"):
        validate_submission(tmp_path / "nope")


def test_never_unpickles(good, tmp_path, monkeypatch):
    class Boom:
        def __reduce__(self):
            return (exec, ("raise SystemExit('unpickled!')",))

    payload = pickle.dumps(Boom())
    (good / "disp_maps" / "evil.npy").write_bytes(payload)
    (good / "runtimes" / "dots.txt").write_bytes(payload)

    def refuse(*args, **kwargs):
        raise AssertionError("the validator must not unpickle or np.load anything")

    monkeypatch.setattr(pickle, "loads", refuse)
    monkeypatch.setattr(pickle, "load", refuse)
    monkeypatch.setattr(pickle, "Unpickler", refuse)
    monkeypatch.setattr(np, "load", refuse)
    for path in (good, zip_folder(good, tmp_path / "p.zip")):
        got = _problems(validate_submission(path, size=SIZE))
        assert len(got) == 2 and any("evil.npy: unexpected file" in g for g in got)


# --------------------------------------------------------------------------- CLI


def test_cli_ok(good, capsys):
    assert main(["validate-submission", str(good), "--size", "16"]) == 0
    out, err = capsys.readouterr()
    assert out == "OK: 12 scenes\n" and err == ""
    assert main(["validate-submission", str(good), "--size", "16", "--scenes", "dots, boxes"]) == 2


def test_cli_lists_problems_on_stdout_and_one_line_on_stderr(good, tmp_path, capsys):
    zpath = _zip_with(good, tmp_path, ("../escape.txt", b"x"), ("junk.bin", b"y"))
    assert main(["validate-submission", zpath, "--size", "16"]) == 2
    out, err = capsys.readouterr()
    assert out.splitlines() == [f"{zpath}:../escape.txt: '..' in the path (escapes the submission folder)",
                                f"{zpath}:junk.bin: unexpected file"]
    lines = err.splitlines()
    assert len(lines) == 1 and "Traceback" not in err
    assert lines[0].startswith(f"lfbench validate-submission: error: {zpath}: invalid submission: 2 problems")
    assert "escape.txt" in lines[0]


def test_cli_real_published_submission(shared_data, capsys):
    published = shared_data / "published" / "subfocal"
    if not published.is_dir():
        pytest.skip("published maps not available")
    assert main(["validate-submission", str(published)]) == 0
    assert capsys.readouterr().out == "OK: 12 scenes\n"


def test_nested_zip_names_missing_files_with_its_folder(good, tmp_path):
    (good / "disp_maps" / "dots.pfm").unlink()
    zpath = zip_folder(good, tmp_path / "nested.zip", prefix="mymethod/")
    assert _problems(validate_submission(zpath, size=SIZE)) == [f"{zpath}:mymethod/disp_maps/dots.pfm: missing"]


def test_zip_with_a_macos_folder_beside_the_submission(good, tmp_path):
    junk = [("__MACOSX/mymethod/disp_maps/._dots.pfm", b"x"), ("__MACOSX/mymethod/disp_maps/dots.pfm", b"x")]
    zpath = zip_folder(good, tmp_path / "mac.zip", prefix="mymethod/", extra=junk)
    assert sorted(_problems(validate_submission(zpath, size=SIZE))) == [
        f"{zpath}:__MACOSX/mymethod/disp_maps/._dots.pfm: unexpected file",
        f"{zpath}:__MACOSX/mymethod/disp_maps/dots.pfm: unexpected file"]


def test_corrupt_zip_member_is_a_problem_not_a_crash(tmp_path):
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_STORED) as zf:
        zf.writestr("disp_maps/a.pfm", pfm_bytes(np.ones((4, 4), np.float32)))
        zf.writestr("runtimes/a.txt", "1.0")
    data = bytearray(buf.getvalue())
    data[data.index(b"Pf\n4 4") + 20] ^= 0xFF  # flip a payload byte: CRC mismatch on read
    (tmp_path / "bad.zip").write_bytes(bytes(data))
    got = _problems(validate_submission(tmp_path / "bad.zip", scenes=["a"], size=(4, 4)))
    assert got == [f"{tmp_path / 'bad.zip'}:disp_maps/a.pfm: cannot read member: Bad CRC-32 for file 'disp_maps/a.pfm'"]
