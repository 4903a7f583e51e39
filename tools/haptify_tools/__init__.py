"""Developer tools that are not part of the standard: schema generation, fixture builders."""
