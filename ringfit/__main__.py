from ringfit.cli import run

run()
