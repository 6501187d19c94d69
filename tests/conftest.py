import os

import jax

jax.config.update("jax_enable_x64", True)

# Heavier cases run at a small size unless JFLEX_SLOW=1.
SLOW = os.environ.get("JFLEX_SLOW", "0") == "1"
