"""hopper_ros: ROS 2 stack for a one-legged hopping robot (messages in hopper_ros.msg)."""
# The generated message code (hopper_ros.msg and its typesupport extensions) may live in
# another sys.path entry than these sources (make setup installs it apart from the editable
# source package): merge every hopper_ros directory on sys.path into this package.
from pkgutil import extend_path

__path__ = extend_path(__path__, __name__)
