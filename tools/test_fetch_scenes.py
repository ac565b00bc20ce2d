"""Tests of tools/fetch-scenes, without the network: downloads come from file:// URLs or from
an http.server on 127.0.0.1 serving a temporary directory.

    python3 -m unittest discover -s tools -p 'test_*.py'
"""

import hashlib
import http.server
import importlib.machinery
import importlib.util
import io
import json
import os
import re
import sys
import tarfile
import tempfile
import threading
import unittest
import urllib.request
from pathlib import Path
from unittest import mock

TOOLS = Path(__file__).resolve().parent
_loader = importlib.machinery.SourceFileLoader("fetch_scenes", str(TOOLS / "fetch-scenes"))
_spec = importlib.util.spec_from_loader("fetch_scenes", _loader)
fetch = importlib.util.module_from_spec(_spec)
sys.modules["fetch_scenes"] = fetch  # dataclasses look their module up there
_loader.exec_module(fetch)


def sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


class Sandbox(unittest.TestCase):
    """A source directory served as file:// URLs, a destination directory and a manifest."""

    def setUp(self):
        tmp = tempfile.TemporaryDirectory()
        self.addCleanup(tmp.cleanup)
        self.tmp = Path(tmp.name)
        self.src = self.tmp / "src"
        self.dest = self.tmp / "scenes"
        self.src.mkdir()

    def serve(self, name: str, data: bytes) -> str:
        path = self.src / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)
        return path.as_uri()

    def manifest(self, files=(), archives=()) -> Path:
        m = self.tmp / "manifest.json"
        m.write_text(json.dumps({"files": list(files), "archives": list(archives)}))
        return m

    def run_fetch(self, *args):
        out, err = io.StringIO(), io.StringIO()
        code = fetch.main([*map(str, args)], out=out, err=err)
        return code, out.getvalue(), err.getvalue()

    def leftovers(self):
        """Every file under the destination (temporary files included)."""
        return sorted(str(p.relative_to(self.dest)) for p in self.dest.rglob("*") if p.is_file()) if self.dest.exists() else []

    def empty_dirs(self):
        """Every empty directory at or under the destination."""
        if not self.dest.exists():
            return []
        return sorted(str(d) for d in [self.dest, *self.dest.rglob("*")] if d.is_dir() and not any(d.iterdir()))


class PlainFiles(Sandbox):
    def test_a_good_file_lands_under_its_name_with_its_sha256(self):
        data = b"<COLLADA>a scene</COLLADA>\n" * 1000
        url = self.serve("dae/sky/CBtest.dae", data)
        m = self.manifest([{"name": "cs184/sky/CBtest.dae", "url": url, "size": len(data), "sha256": sha(data)}])
        code, out, err = self.run_fetch("--manifest", m, "--dir", self.dest)
        self.assertEqual(code, 0, err)
        got = self.dest / "cs184/sky/CBtest.dae"
        self.assertEqual(sha(got.read_bytes()), sha(data))
        self.assertEqual(self.leftovers(), ["cs184/sky/CBtest.dae"])
        self.assertIn(f"export RAYPACK_SCENES={self.dest}", out)
        self.assertIn(str(got), out)
        # A second run finds it and downloads nothing.
        os.unlink(self.src / "dae/sky/CBtest.dae")
        code, out, err = self.run_fetch("--manifest", m, "--dir", self.dest)
        self.assertEqual(code, 0, err)
        self.assertIn("already there", out)

    def test_a_checksum_mismatch_is_rejected_and_leaves_nothing(self):
        data = b"the bytes the server really has\n"
        url = self.serve("dae/sky/CBbad.dae", data)
        wrong = sha(b"the bytes the manifest was made from\n")
        m = self.manifest([{"name": "cs184/sky/CBbad.dae", "url": url, "size": len(data), "sha256": wrong}])
        code, out, err = self.run_fetch("--manifest", m, "--dir", self.dest)
        self.assertEqual(code, 1)
        self.assertIn(url, err)
        self.assertIn(f"expected {wrong}", err)
        self.assertIn(f"got {sha(data)}", err)
        self.assertFalse((self.dest / "cs184/sky/CBbad.dae").exists())
        self.assertEqual(self.leftovers(), [], "the temporary file must be removed")
        self.assertEqual(self.empty_dirs(), [], "the directories made for it must be removed")
        self.assertNotIn("export RAYPACK_SCENES", out)

    def test_a_mismatch_does_not_replace_a_file_already_there(self):
        data = b"new bytes from a changed server\n"
        url = self.serve("x.dae", data)
        m = self.manifest([{"name": "cs184/x.dae", "url": url, "size": len(data), "sha256": sha(b"pinned\n")}])
        (self.dest / "cs184").mkdir(parents=True)
        (self.dest / "cs184/x.dae").write_bytes(b"older local copy\n")
        code, _, _ = self.run_fetch("--manifest", m, "--dir", self.dest)
        self.assertEqual(code, 1)
        self.assertEqual((self.dest / "cs184/x.dae").read_bytes(), b"older local copy\n")
        self.assertEqual(self.leftovers(), ["cs184/x.dae"])

    def test_a_download_longer_than_its_size_is_cut_off_and_removed(self):
        data = b"x" * 5000
        url = self.serve("big.dae", data)
        m = self.manifest([{"name": "cs184/big.dae", "url": url, "size": 100, "sha256": sha(data[:100])}])
        code, _, err = self.run_fetch("--manifest", m, "--dir", self.dest)
        self.assertEqual(code, 1)
        self.assertIn("more than the expected 100 bytes", err)
        self.assertEqual(self.leftovers(), [])

    def test_an_unknown_sha256_is_refused_unless_trust_size(self):
        data = b"a file nobody pinned\n"
        url = self.serve("u.ply", data)
        m = self.manifest([{"name": "models/u.ply", "url": url, "size": len(data), "sha256": None}])
        code, _, err = self.run_fetch("--manifest", m, "--dir", self.dest)
        self.assertEqual(code, 1)
        self.assertIn(sha(data), err, "the sha256 seen is printed so that it can be pinned")
        self.assertIn("--trust-size", err)
        self.assertEqual(self.leftovers(), [])
        code, _, err = self.run_fetch("--manifest", m, "--dir", self.dest, "--trust-size")
        self.assertEqual(code, 0, err)
        self.assertEqual((self.dest / "models/u.ply").read_bytes(), data)
        self.assertIn(sha(data), err)

    def test_over_http(self):
        good, bad = b"served over http\n", b"tampered on the way\n"
        self.serve("good.dae", good)
        self.serve("bad.dae", bad)
        src = str(self.src)

        class Quiet(http.server.SimpleHTTPRequestHandler):
            def __init__(self, *a, **k):
                super().__init__(*a, directory=src, **k)

            def log_message(self, *a):
                pass

        server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Quiet)
        threading.Thread(target=server.serve_forever, daemon=True).start()
        self.addCleanup(server.server_close)
        self.addCleanup(server.shutdown)
        base = f"http://127.0.0.1:{server.server_address[1]}"
        m = self.manifest(
            [
                {"name": "cs184/good.dae", "url": f"{base}/good.dae", "size": len(good), "sha256": sha(good)},
                {"name": "cs184/bad.dae", "url": f"{base}/bad.dae", "size": len(bad), "sha256": sha(good)},
            ]
        )
        code, out, err = self.run_fetch("--manifest", m, "--dir", self.dest)
        self.assertEqual(code, 1)
        self.assertIn(f"{base}/bad.dae: sha256 mismatch: expected {sha(good)}, got {sha(bad)}", err)
        self.assertEqual(self.leftovers(), ["cs184/good.dae"])
        self.assertEqual((self.dest / "cs184/good.dae").read_bytes(), good)

    def test_only_selects_by_group_or_file(self):
        a, b = b"aaa\n", b"bbb\n"
        m = self.manifest(
            [
                {"name": "cs184/sky/a.dae", "url": self.serve("a", a), "size": 4, "sha256": sha(a)},
                {"name": "cs184/basic/b.dae", "url": self.serve("b", b), "size": 4, "sha256": sha(b)},
            ]
        )
        self.assertEqual(self.run_fetch("--manifest", m, "--dir", self.dest, "--only", "cs184/sky")[0], 0)
        self.assertEqual(self.leftovers(), ["cs184/sky/a.dae"])
        code, _, err = self.run_fetch("--manifest", m, "--dir", self.dest, "--only", "nosuch")
        self.assertEqual(code, 1)
        self.assertIn("--only nosuch: no such item", err)


class DryRun(Sandbox):
    def test_dry_run_lists_everything_and_touches_nothing(self):
        data = b"payload\n"
        files = [{"name": "cs184/sky/A.dae", "url": self.serve("A.dae", data), "size": len(data), "sha256": sha(data)}]
        archives = [
            {
                "name": "stanford-thing",
                "url": "https://example.invalid/thing.tar.gz",
                "size": 1234,
                "sha256": "ab" * 32,
                "members": [{"member": "thing/thing.ply", "dest": "models/thing.ply", "size": None, "sha256": None}],
            }
        ]
        m = self.manifest(files, archives)
        with mock.patch.object(urllib.request, "urlopen", side_effect=AssertionError("network used")):
            code, out, err = self.run_fetch("--manifest", m, "--dir", self.dest, "--dry-run")
        self.assertEqual(code, 0, err)
        self.assertFalse(self.dest.exists(), "--dry-run must not create the destination")
        for line, entry in ((l, e) for e in files + archives for l in out.splitlines() if l.startswith(e["name"] + " ")):
            self.assertIn(entry["url"], line)
            self.assertIn(f"{entry['size']:,} bytes", line)
            self.assertIn(entry["sha256"], line)
        self.assertEqual(sum(1 for l in out.splitlines() if l.startswith(("cs184/", "stanford-"))), 2)
        self.assertIn("thing/thing.ply -> models/thing.ply  size unknown", out)

    def test_the_real_manifest_is_well_formed(self):
        items = fetch.load_manifest(fetch.MANIFEST)
        out = io.StringIO()
        fetch.dry_run(items, Path("/nowhere"), out)
        dests = [d for i in items for d in i.dests()]
        self.assertEqual(len(dests), len(set(dests)))
        for needed in ("cs184/sky/CBbunny.dae", "cs184/sky/CBspheres.dae", "cs184/meshedit/beetle.dae", "models/stanford-dragon-871k.ply"):
            self.assertIn(needed, dests)
        for i in items:
            self.assertTrue(i.url.startswith("https://"), i.url)
            self.assertIn(i.url, out.getvalue())
            for s in [i.sha256] + [m.sha256 for m in i.members]:
                self.assertTrue(s is None or re.fullmatch("[0-9a-f]{64}", s), s)
            # Files fetched from GitHub are pinned to a commit, not a branch.
            if "githubusercontent" in i.url:
                self.assertRegex(i.url, "/[0-9a-f]{40}/")

    def test_the_manifest_agrees_with_the_scenes_in_raypack_scenes(self):
        root = os.environ.get("RAYPACK_SCENES")
        if not root:
            self.skipTest("SKIPPED: RAYPACK_SCENES is not set")
        checked = 0
        for item in fetch.load_manifest(fetch.MANIFEST):
            entries = [(m.dest, m.size, m.sha256) for m in item.members] or [(item.name, item.size, item.sha256)]
            for dest, size, digest in entries:
                path = Path(root) / dest
                if digest and path.is_file():
                    self.assertEqual(path.stat().st_size, size, dest)
                    self.assertEqual(fetch.sha256_of(path), digest, dest)
                    checked += 1
        if not checked:
            self.skipTest(f"SKIPPED: none of the manifest's files is under {root}")


class Archives(Sandbox):
    def make_tar(self, members: dict) -> tuple[str, bytes]:
        buf = io.BytesIO()
        with tarfile.open(fileobj=buf, mode="w:gz") as tf:
            for name, data in members.items():
                info = tarfile.TarInfo(name)
                if data is None:  # a symbolic link
                    info.type, info.linkname = tarfile.SYMTYPE, "/etc/passwd"
                else:
                    info.size = len(data)
                tf.addfile(info, None if data is None else io.BytesIO(data))
        blob = buf.getvalue()
        return self.serve("recon.tar.gz", blob), blob

    def archive(self, url, blob, members):
        return {"name": "stanford-test", "url": url, "size": len(blob), "sha256": sha(blob), "members": members}

    def test_named_members_are_extracted_and_the_archive_removed(self):
        full, low = b"ply\nfull\n", b"ply\nlow\n"
        url, blob = self.make_tar({"recon/full.ply": full, "recon/low.ply": low, "recon/README": b"x"})
        members = [
            {"member": "recon/full.ply", "dest": "models/full.ply", "size": len(full), "sha256": sha(full)},
            {"member": "recon/low.ply", "dest": "models/low.ply", "size": None, "sha256": None},
        ]
        code, out, err = self.run_fetch("--manifest", self.manifest(archives=[self.archive(url, blob, members)]), "--dir", self.dest)
        self.assertEqual(code, 0, err)
        self.assertEqual(self.leftovers(), ["models/full.ply", "models/low.ply"])
        self.assertEqual((self.dest / "models/low.ply").read_bytes(), low)
        self.assertIn(sha(low), err, "a member without its own sha256 has it printed")

    def test_a_member_with_dotdot_is_refused(self):
        evil = b"outside the cache\n"
        url, blob = self.make_tar({"../evil.ply": evil, "recon/ok.ply": b"ok\n"})
        members = [{"member": "../evil.ply", "dest": "models/evil.ply", "size": len(evil), "sha256": sha(evil)}]
        code, _, err = self.run_fetch("--manifest", self.manifest(archives=[self.archive(url, blob, members)]), "--dir", self.dest)
        self.assertEqual(code, 1)
        self.assertIn("refusing archive member '../evil.ply'", err)
        self.assertFalse((self.dest / "models/evil.ply").exists())
        self.assertFalse((self.dest.parent / "evil.ply").exists())
        # Neither the downloaded archive nor an empty directory is left (both were, before).
        self.assertEqual(self.leftovers(), [])
        self.assertEqual(self.empty_dirs(), [])

    def test_an_absolute_or_link_member_is_refused(self):
        url, blob = self.make_tar({"recon/link.ply": None, "recon/ok.ply": b"ok\n"})
        for member, why in (("/etc/passwd", "not a relative path"), ("recon/link.ply", "not a regular file")):
            members = [{"member": member, "dest": "models/x.ply", "size": None, "sha256": None}]
            code, _, err = self.run_fetch("--manifest", self.manifest(archives=[self.archive(url, blob, members)]), "--dir", self.dest)
            self.assertEqual(code, 1)
            self.assertIn(why, err)
            self.assertFalse((self.dest / "models/x.ply").exists())

    def test_a_destination_outside_the_directory_is_refused(self):
        m = self.manifest([{"name": "../outside.dae", "url": self.serve("o", b"o"), "size": 1, "sha256": sha(b"o")}])
        code, _, err = self.run_fetch("--manifest", m, "--dir", self.dest)
        self.assertEqual(code, 1)
        self.assertIn("not a safe relative path", err)
        self.assertFalse((self.tmp / "outside.dae").exists())

    def test_a_tampered_archive_is_rejected_before_extraction(self):
        full = b"ply\nfull\n"
        url, blob = self.make_tar({"recon/full.ply": full})
        entry = self.archive(url, blob, [{"member": "recon/full.ply", "dest": "models/full.ply", "size": None, "sha256": None}])
        entry["sha256"] = sha(b"another archive")
        code, _, err = self.run_fetch("--manifest", self.manifest(archives=[entry]), "--dir", self.dest)
        self.assertEqual(code, 1)
        self.assertIn("sha256 mismatch", err)
        self.assertEqual(self.leftovers(), [])


class Manifests(Sandbox):
    def test_a_malformed_manifest_is_an_error_naming_the_field_not_a_traceback(self):
        good = {"name": "cs184/a.dae", "url": "https://example.invalid/a.dae", "size": 3, "sha256": "ab" * 32}
        member = {"member": "a/b.ply", "dest": "models/b.ply", "size": None, "sha256": None}
        archive = {"name": "thing", "url": "https://example.invalid/t.tgz", "size": 9, "sha256": None, "members": [member]}
        cases = [
            ([1, 2], "expected an object, got list"),
            ({"files": {"name": "x"}}, "files: expected a list"),
            ({"files": ["x"]}, "files[0]: expected an object, got str"),
            ({"files": [{**good, "name": None}]}, "files[0].name: expected a non-empty string, got None"),
            ({"files": [{k: v for k, v in good.items() if k != "url"}]}, "files[0].url: expected a non-empty string"),
            ({"files": [{**good, "size": "3"}]}, "files[0].size: expected a whole number of bytes or null, got '3'"),
            ({"files": [{**good, "sha256": "nope"}]}, "files[0].sha256: expected 64 lowercase hex digits or null"),
            ({"archives": [{**archive, "members": None}]}, "archives[0].members: expected a list, got None"),
            ({"archives": [{k: v for k, v in archive.items() if k != "members"}]}, "archives[0].members: expected a list"),
            ({"archives": [{**archive, "members": [{**member, "dest": 7}]}]}, "archives[0].members[0].dest: expected a non-empty string, got 7"),
        ]
        for data, message in cases:
            m = self.tmp / "manifest.json"
            m.write_text(json.dumps(data))
            for extra in ((), ("--dry-run",)):
                code, out, err = self.run_fetch("--manifest", m, "--dir", self.dest, *extra)
                self.assertEqual(code, 1, (data, err))
                self.assertIn(f"{m}: {message}", err)
                self.assertNotIn("Traceback", err)
            self.assertFalse(self.dest.exists())


if __name__ == "__main__":
    unittest.main()


class Selection(Sandbox):
    """What is fetched without --only: the default entries; --all adds the rest."""

    def setup_two(self):
        small, big = b"small\n", b"big\n"
        files = [{"name": "cs184/sky/small.dae", "url": self.serve("small.dae", small), "size": len(small), "sha256": sha(small)}]
        big_entry = {"name": "models/big.ply", "url": self.serve("big.ply", big), "size": len(big), "sha256": sha(big), "default": False}
        return self.manifest(files + [big_entry])

    def test_entries_marked_not_default_need_all_or_only(self):
        m = self.setup_two()
        code, _, err = self.run_fetch("--manifest", m, "--dir", self.dest)
        self.assertEqual(code, 0, err)
        self.assertEqual(self.leftovers(), ["cs184/sky/small.dae"])
        self.assertIn("not fetched without --all (or --only NAME): models/big.ply", err)
        self.assertEqual(self.run_fetch("--manifest", m, "--dir", self.dest, "--only", "models/big.ply")[0], 0)
        self.assertEqual(self.leftovers(), ["cs184/sky/small.dae", "models/big.ply"])
        (self.dest / "models/big.ply").unlink()
        self.assertEqual(self.run_fetch("--manifest", m, "--dir", self.dest, "--all")[0], 0)
        self.assertEqual(self.leftovers(), ["cs184/sky/small.dae", "models/big.ply"])
        code, _, err = self.run_fetch("--manifest", m, "--dir", self.dest, "--all", "--only", "cs184")
        self.assertEqual(code, 1)
        self.assertIn("--all and --only", err)

    def test_a_non_boolean_default_is_an_error_naming_the_field(self):
        m = self.manifest([{"name": "a.dae", "url": "https://example.invalid/a.dae", "size": 1, "sha256": None, "default": "no"}])
        code, _, err = self.run_fetch("--manifest", m, "--dir", self.dest, "--dry-run")
        self.assertEqual(code, 1)
        self.assertIn("files[0].default: expected true or false, got 'no'", err)

    def test_the_real_manifest_fetches_cs184_and_the_dragon_by_default_not_lucy(self):
        items = fetch.select(fetch.load_manifest(fetch.MANIFEST), None)
        dests = [d for i in items for d in i.dests()]
        self.assertIn("cs184/sky/CBbunny.dae", dests)
        self.assertIn("models/stanford-dragon-871k.ply", dests)
        self.assertTrue(all(i.name.startswith("cs184/") or i.name == "stanford-dragon" for i in items), [i.name for i in items])
        self.assertNotIn("models/lucy-28m.ply", dests)
        everything = fetch.select(fetch.load_manifest(fetch.MANIFEST), None, everything=True)
        self.assertIn("models/lucy-28m.ply", [d for i in everything for d in i.dests()])


class FromDirectory(Sandbox):
    """--from DIR: archives and files downloaded by hand, checked, used in place, never moved."""

    make_tar = Archives.make_tar
    archive = Archives.archive

    def setUp(self):
        super().setUp()
        self.hand = self.tmp / "downloads"
        self.hand.mkdir()

    def no_network(self):
        return mock.patch.object(urllib.request, "urlopen", side_effect=AssertionError("network used"))

    def test_an_archive_downloaded_by_hand_is_extracted_and_left_in_place(self):
        full = b"ply\nfull\n"
        _, blob = self.make_tar({"recon/full.ply": full})
        (self.hand / "recon.tar.gz").write_bytes(blob)
        members = [{"member": "recon/full.ply", "dest": "models/full.ply", "size": len(full), "sha256": sha(full)}]
        entry = self.archive("https://example.invalid/pub/recon.tar.gz", blob, members)
        with self.no_network():
            code, _, err = self.run_fetch("--manifest", self.manifest(archives=[entry]), "--dir", self.dest, "--from", self.hand)
        self.assertEqual(code, 0, err)
        self.assertEqual(self.leftovers(), ["models/full.ply"])
        self.assertEqual((self.dest / "models/full.ply").read_bytes(), full)
        self.assertEqual((self.hand / "recon.tar.gz").read_bytes(), blob, "the user's archive stays")

    def test_a_wrong_archive_in_from_is_refused_and_nothing_is_written(self):
        full = b"ply\nfull\n"
        _, blob = self.make_tar({"recon/full.ply": full})
        (self.hand / "recon.tar.gz").write_bytes(blob + b"tampered")
        members = [{"member": "recon/full.ply", "dest": "models/full.ply", "size": len(full), "sha256": sha(full)}]
        entry = self.archive("https://example.invalid/pub/recon.tar.gz", blob, members)
        with self.no_network():
            code, _, err = self.run_fetch("--manifest", self.manifest(archives=[entry]), "--dir", self.dest, "--from", self.hand)
        self.assertEqual(code, 1)
        self.assertIn("recon.tar.gz (given by --from", err)
        self.assertIn("sha256 mismatch", err)
        self.assertEqual(self.leftovers(), [])
        self.assertTrue((self.hand / "recon.tar.gz").exists(), "the user's file is not removed")

    def test_plain_files_by_name_or_path_and_the_rest_downloaded(self):
        a, b = b"aaa\n", b"bbb\n"
        (self.hand / "a.dae").write_bytes(a)
        files = [
            {"name": "cs184/sky/a.dae", "url": "https://example.invalid/x/a.dae", "size": len(a), "sha256": sha(a)},
            {"name": "cs184/sky/b.dae", "url": self.serve("b.dae", b), "size": len(b), "sha256": sha(b)},
        ]
        code, _, err = self.run_fetch("--manifest", self.manifest(files), "--dir", self.dest, "--from", self.hand)
        self.assertEqual(code, 0, err)
        self.assertEqual(self.leftovers(), ["cs184/sky/a.dae", "cs184/sky/b.dae"])
        self.assertIn("cs184/sky/b.dae: not in", err)
        self.assertTrue((self.hand / "a.dae").exists())

    def test_from_a_missing_directory_is_an_error(self):
        code, _, err = self.run_fetch("--manifest", self.manifest(), "--dir", self.dest, "--from", self.tmp / "nosuch")
        self.assertEqual(code, 1)
        self.assertIn("--from", err)
        self.assertIn("not a directory", err)
