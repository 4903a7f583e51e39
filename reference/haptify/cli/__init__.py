"""The ``haptify`` command, thin (spec §0.5): the entry point and parser (:mod:`.main`), the output policy
(:mod:`.ui`) and one module per sub-command (``cmd_<name>``, registered under the entry-point group
``haptify.commands``) that parses arguments and calls the packages that do the work. The package imports
none of its modules, so that ``haptify --help`` loads no heavy package.
"""
