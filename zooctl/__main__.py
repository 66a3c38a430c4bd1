from zooctl.cli.main import entry

entry()
