"""``sim_core.files``: the one atomic write (permissions from the umask, secrets 0600, whole or
nothing) and parse errors that name the file, the line and the column."""

import os
import stat

import numpy as np
import pytest

from sim_core.files import (
    StructuredFileError,
    atomic_write,
    current_umask,
    load_structured,
)


def _mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


@pytest.mark.parametrize(("mask", "mode"), [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_a_written_file_gets_the_permissions_the_umask_gives_a_new_file(tmp_path, umask, mask,
                                                                         mode):
    umask(mask)
    assert current_umask() == mask
    path = atomic_write(tmp_path / "a.txt", "hello\n")
    assert path.read_text() == "hello\n"
    assert _mode(path) == mode
    with open(tmp_path / "plain.txt", "w") as fh:  # what open() gives: the same
        fh.write("x")
    assert _mode(tmp_path / "plain.txt") == mode


def test_a_secret_is_owner_only_whatever_the_umask(tmp_path, umask):
    umask(0o002)
    path = atomic_write(tmp_path / "token", b"s3cret\n", secret=True)
    assert _mode(path) == 0o600 and path.read_bytes() == b"s3cret\n"


def test_an_existing_file_is_replaced_and_a_writer_function_gets_a_binary_file(tmp_path):
    target = tmp_path / "a.npz"
    target.write_text("old")
    atomic_write(target, lambda fh: np.savez_compressed(fh, x=np.arange(3)))
    with np.load(target) as z:
        assert z["x"].tolist() == [0, 1, 2]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.npz"]  # no temporary left


def test_a_failing_writer_leaves_the_target_as_it_was_and_no_temporary(tmp_path):
    target = tmp_path / "frame.json"
    target.write_text("previous")

    def broken(fh):
        fh.write(b"half a fi")
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        atomic_write(target, broken)
    assert target.read_text() == "previous"
    assert [p.name for p in tmp_path.iterdir()] == ["frame.json"]


@pytest.mark.parametrize(("name", "text", "where", "what"), [
    ("scene.yaml", "camera:\n  preset: x\n bad: 1\n", ":3:2: ", "invalid YAML: expected"),
    ("scene.yaml", "name: 'open\n", ":2:1: ", "invalid YAML: found unexpected end of stream"),
    ("scene.yml", "a:\n\t- b\n", ":2:1: ", "invalid YAML: found character '\\t'"),
    ("twin.json", '{\n  "a": 1,\n}\n', ":3:1: ", "invalid JSON: Expecting property name"),
])
def test_a_parse_error_names_the_file_line_and_column(tmp_path, name, text, where, what):
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(StructuredFileError) as info:
        load_structured(path)
    message = str(info.value)
    assert message.startswith(f"{path}{where}{what}"), message
    assert "<unicode string>" not in message


def test_a_byte_that_is_not_utf8_is_placed_too(tmp_path):
    path = tmp_path / "scene.yaml"
    path.write_bytes(b"name: ok\ndescription: caf\xe9\n")
    with pytest.raises(StructuredFileError,
                       match=r"scene\.yaml:2:17: not UTF-8 text \(byte 0xe9\)"):
        load_structured(path)


def test_yaml_reads_json_and_a_json_file_is_read_as_json(tmp_path):
    (tmp_path / "a.yaml").write_text('{"a": [1, 2]}')
    (tmp_path / "b.json").write_text('{"b": true}')
    assert load_structured(tmp_path / "a.yaml") == {"a": [1, 2]}
    assert load_structured(tmp_path / "b.json") == {"b": True}
