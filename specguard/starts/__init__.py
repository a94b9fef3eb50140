"""Start spaces: the states an episode may begin from, and how an env is put in one (built-in setters, joints)."""
