import subprocess
import sys


def test_package_and_cli_parser_do_not_import_the_card_builder():
    code = ("import sys, cghair_format; from cghair_format.cli import build_parser; build_parser(); "
            "bad = [m for m in ('sklearn', 'cghair_format.cards') if m in sys.modules]; "
            "print(bad); sys.exit(1 if bad else 0)")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stdout + res.stderr
