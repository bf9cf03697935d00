: pp-test pp 1 1 op-mode! until-no-requests 1 1 reset-fault 1 1 until-no-fault 1 1 drive-on 1 1 until-drive-on 1000 1 1 target-p! 1 1 go 1 1 until-target-reached ." reached " 1 1 real-p@ . cr ;
deploy pp-test ;deploy
