"""The camera bridge alone, in a venv holding only numpy and pytest (``.ci/bridge-alone``)."""
