: home hm 1 1 op-mode! 35 1 1 homing-method! until-no-requests 1 1 drive-on 1 1 until-drive-on 1 1 go 1 1 until-target-reached 1 1 +drive-homed ;
deploy home ;deploy
