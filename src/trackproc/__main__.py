from trackproc.cli.app import run

run()
