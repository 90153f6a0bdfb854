//! Host-side support for touchdown: image files, the command-line tool and test helpers.
