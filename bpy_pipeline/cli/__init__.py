"""The command line, one module per subcommand: ``run`` (:mod:`.run`, also ``python run.py``), ``convert``
(:mod:`.convert`), ``match`` (:mod:`.match`) and the tiles export (:mod:`.tiles`); ``bpy_pipeline/__main__.py``
dispatches ``bpy-pipeline <subcommand>`` to them."""
