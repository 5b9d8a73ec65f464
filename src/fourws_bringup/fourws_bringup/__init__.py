"""fourws_bringup (see the package.xml description)."""

import fourws_common  # noqa: F401 - first: sets the BLAS thread default before numpy loads
